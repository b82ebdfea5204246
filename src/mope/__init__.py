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
import importlib.abc
import importlib.machinery
import importlib.util
import sys
from types import ModuleType
from typing import Any

from mope.agent.agent import EQL, MoPE, TrainingDivergedError, make_agent
from mope.config import ALGOS, Config
from mope.envs import make_env
from mope.errors import CheckpointError, ConfigError, MopeError, PreferenceError
from mope.evaluation.evaluator import Evaluator, Solutions, solutions

#: Modules that moved into subpackages: the old path imports the new module (the same module object).
#: ``mope.agent``, ``mope.evaluation`` and ``mope.experiments`` are packages now; they serve the names of the
#: former modules (``mope.agent.agent``, ``mope.evaluation.evaluator``, ``mope.experiments.runs``) themselves.
MOVED_MODULES = {
    "mope.agent_state": "mope.agent.agent_state",
    "mope.base": "mope.agent.base",
    "mope.checkpoint": "mope.agent.checkpoint",
    "mope.demonstrations": "mope.agent.demonstrations",
    "mope.losses": "mope.agent.losses",
    "mope.networks": "mope.agent.networks",
    "mope.replay": "mope.agent.replay",
    "mope.runner": "mope.agent.runner",
    "mope.targets": "mope.agent.targets",
    "mope.diagnose": "mope.evaluation.diagnose",
    "mope.diversity": "mope.evaluation.diversity",
    "mope.game_probe": "mope.evaluation.game_probe",
    "mope.video": "mope.evaluation.video",
    "mope.jobs": "mope.experiments.jobs",
    "mope.locks": "mope.experiments.locks",
    "mope.plots": "mope.experiments.plots",
    "mope.report": "mope.experiments.report",
    "mope.sweep": "mope.experiments.sweep",
    "mope.baselines": "mope.paper.ppo",
    "mope.benchmark": "mope.paper.benchmark",
    "mope.peers": "mope.paper.envelope",
    "mope.reproduce": "mope.paper.dst",
    "mope.reproduce_confrontation": "mope.paper.confrontation",
}


class _MovedModuleLoader(importlib.abc.Loader):
    """Loads an old module path as the module at its new path (one module object under two names)."""

    def __init__(self, target: str) -> None:
        self.target = target
        self.spec: importlib.machinery.ModuleSpec | None = None

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        module = importlib.import_module(self.target)
        self.spec = module.__spec__
        return module

    def exec_module(self, module: ModuleType) -> None:
        module.__spec__ = self.spec  # the import machinery gave it the old name's spec in between


class _MovedModuleFinder(importlib.abc.MetaPathFinder):
    """Finds the old paths of :data:`MOVED_MODULES`."""

    def find_spec(self, fullname: str, path: Any = None, target: Any = None) -> importlib.machinery.ModuleSpec | None:
        new = MOVED_MODULES.get(fullname)
        return None if new is None else importlib.util.spec_from_loader(fullname, _MovedModuleLoader(new))


if not any(isinstance(f, _MovedModuleFinder) for f in sys.meta_path):
    sys.meta_path.append(_MovedModuleFinder())


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
