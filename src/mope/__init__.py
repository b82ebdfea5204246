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
from typing import Any

from mope.agent.agent import EQL, MoPE, TrainingDivergedError, make_agent
from mope.config import ALGOS, Config
from mope.envs import make_env
from mope.errors import CheckpointError, ConfigError, MopeError, PreferenceError
from mope.evaluation.evaluator import Evaluator, Solutions, solutions
from mope.moved import MOVED_MODULES


def __getattr__(name: str) -> Any:
    """``mope.replay`` and the other old paths as attributes, imported on first use."""
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
