"""Old module paths after the move into subpackages (mope 0.2 had 30 modules side by side in ``src/mope``).

``import mope.replay`` still imports :mod:`mope.agent.replay` (the same module object, through a finder on
``sys.meta_path``), and ``from mope.agent import MoPE`` still finds the names of the former module ``mope.agent``
(now :mod:`mope.agent.agent`) through the package's ``__getattr__`` (:func:`former_module_names`).
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import importlib.util
import sys
from collections.abc import Callable
from types import ModuleType
from typing import Any

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


def former_module_names(package: str, former: str) -> Callable[[str], Any]:
    """The ``__getattr__`` of a package that took the name of a former module: its submodules, imported on first
    use, then the names of the former module (now ``former``), so that importing one submodule imports no other."""

    def package_getattr(name: str) -> Any:
        if not name.startswith("__"):
            try:
                return importlib.import_module(f"{package}.{name}")
            except ModuleNotFoundError as exc:
                if exc.name != f"{package}.{name}":
                    raise
            try:
                return getattr(importlib.import_module(former), name)
            except AttributeError:
                pass
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return package_getattr


__all__ = ["MOVED_MODULES", "former_module_names"]
