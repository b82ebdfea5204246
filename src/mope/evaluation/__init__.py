"""Evaluation: batched greedy rollouts and the paper's protocol (``evaluator.py``), the exact Q* of
Deep-Sea-Treasure (``diagnose.py``), diversity measures, videos of a rollout, and the game's probes.

``from mope.evaluation import Evaluator`` keeps working: the names of the former module ``mope.evaluation`` (now
:mod:`mope.evaluation.evaluator`) are served from there on first use, so that importing one submodule does not
import the others.
"""

from __future__ import annotations

import importlib
from typing import Any

_FORMER = "mope.evaluation.evaluator"


def __getattr__(name: str) -> Any:
    if not name.startswith("__"):
        try:
            return importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise
        try:
            return getattr(importlib.import_module(_FORMER), name)
        except AttributeError:
            pass
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
