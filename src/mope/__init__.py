"""mope: Multi-objective RL with Preference Exploration.

One preference-conditioned agent that acts well under any trade-off between objectives: Envelope Q-learning
(Yang et al. 2019) with the experience exploration and preference exploration of MoPE (Xi and Guo).

Public API::

    from mope import MoPE, EQL, Config, Evaluator, solutions
    agent = MoPE("deep-sea-treasure-v0", seed=0)
    agent.train(20_000, eval_env=mope.make_env("deep-sea-treasure-v0"), progress=True)

The package, from the bottom up: :mod:`mope.errors`, :mod:`mope.config`, :mod:`mope.preferences` and
:mod:`mope.metrics` at the top level; :mod:`mope.envs` (environments and their batched versions);
:mod:`mope.agent` (the agent, its networks, losses, replay and training loop); :mod:`mope.evaluation` (rollouts,
diagnosis, diversity, videos); :mod:`mope.experiments` (run folders, jobs, sweeps, reports); :mod:`mope.paper`
(the paper's reproductions, the benchmark and its baselines); :mod:`mope.cli` on top.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from mope.config import ALGOS, Config
from mope.envs import make_env
from mope.errors import CheckpointError, ConfigError, MopeError, PreferenceError
from mope.moved import MOVED_MODULES

if TYPE_CHECKING:
    from mope.agent.agent import EQL, MoPE, TrainingDivergedError, make_agent
    from mope.evaluation.evaluator import Evaluator, Solutions, solutions

#: The public names that need torch, imported on first use: ``import mope`` (and so every ``mope`` command that
#: stops at bad input) does not pay torch's 2-4 s import.
_LAZY = {"EQL": "mope.agent.agent", "MoPE": "mope.agent.agent", "TrainingDivergedError": "mope.agent.agent",
         "make_agent": "mope.agent.agent", "Evaluator": "mope.evaluation.evaluator",
         "Solutions": "mope.evaluation.evaluator", "solutions": "mope.evaluation.evaluator"}


def __getattr__(name: str) -> Any:
    """The torch-backed public names (:data:`_LAZY`), and ``mope.replay`` and the other old paths, imported on
    first use."""
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    if f"mope.{name}" in MOVED_MODULES:
        return importlib.import_module(f"mope.{name}")
    raise AttributeError(f"module 'mope' has no attribute {name!r}")


__all__ = [
    "ALGOS",
    "EQL",
    "CheckpointError",
    "Config",
    "ConfigError",
    "Evaluator",
    "MoPE",
    "MopeError",
    "PreferenceError",
    "Solutions",
    "TrainingDivergedError",
    "make_agent",
    "make_env",
    "solutions",
]
