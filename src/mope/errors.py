"""Errors that mope raises for bad input.

Every check at a boundary (CLI flag, API argument, config file, checkpoint) raises a subclass of
:class:`MopeError` with one line that names the bad value and what is allowed. The CLI turns these into
``error: ...`` and exit code 2, without a traceback.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable


class MopeError(ValueError):
    """Base class of every user-facing error in mope."""


class ConfigError(MopeError):
    """A configuration value is unknown or out of range."""


class PreferenceError(MopeError):
    """A preference vector is malformed."""


class EnvironmentError_(MopeError):
    """An environment id is unknown or the environment is not supported."""


class CheckpointError(MopeError):
    """A checkpoint cannot be read, is unsafe, or does not fit."""


def suggest(name: str, choices: Iterable[str]) -> str:
    """Return ``" (did you mean 'x'?)"`` for the closest choice, or an empty string."""
    match = difflib.get_close_matches(name, list(choices), n=1, cutoff=0.5)
    return f" (did you mean '{match[0]}'?)" if match else ""
