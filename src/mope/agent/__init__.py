"""The agent: MoPE and EQL (``agent.py``, built on ``base.py`` and ``agent_state.py``), its networks, losses,
targets, replay buffer and demonstrations, checkpoints, and the training loop with its callbacks (``runner.py``).

``from mope.agent import MoPE`` keeps working: the names of the former module ``mope.agent`` (now
:mod:`mope.agent.agent`) are served from there on first use, so that importing one submodule does not import the
others.
"""

from __future__ import annotations

import importlib
from typing import Any

_FORMER = "mope.agent.agent"


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
