"""Evaluation: batched greedy rollouts and the paper's protocol (``evaluator.py``), the exact Q* of
Deep-Sea-Treasure (``diagnose.py``), diversity measures, videos of a rollout, and the game's probes.

``from mope.evaluation import Evaluator`` keeps working: the names of the former module ``mope.evaluation`` (now
:mod:`mope.evaluation.evaluator`) are served from there on first use (:func:`mope.moved.former_module_names`).
"""

from mope.moved import former_module_names

__getattr__ = former_module_names(__name__, "mope.evaluation.evaluator")
