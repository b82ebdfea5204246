"""Experiments: run folders (``runs.py``), the one executor for batches of jobs (``jobs.py``) and the kinds
of job it runs (``job_kinds.py``), sweeps, reports and their statistics, folder locks and plotting.

``from mope.experiments import train_run`` keeps working: the names of the former module ``mope.experiments`` (now
:mod:`mope.experiments.runs`) are served from there on first use, so that importing one submodule does not
import the others.
"""

from __future__ import annotations

import importlib
from typing import Any

_FORMER = "mope.experiments.runs"


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
