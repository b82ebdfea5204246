"""Errors that mope raises for bad input.

Every check at a boundary (CLI flag, API argument, config file, checkpoint) raises a subclass of
:class:`MopeError` with one line that names the bad value and what is allowed. The CLI turns these into
``error: ...`` and exit code 2, without a traceback.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable


def one_line(text: str) -> str:
    """Collapse ``text`` to one line: runs of whitespace (newlines included) become one space."""
    return " ".join(str(text).split())


class MopeError(ValueError):
    """Base class of every user-facing error in mope.

    The message is always one line: text from elsewhere (a YAML parser, torch, the OS) that spans several lines
    is collapsed, so the CLI can print it as a single ``error: ...`` line.
    """

    def __init__(self, *args: object) -> None:
        if len(args) == 1 and isinstance(args[0], str):
            args = (one_line(args[0]),)
        super().__init__(*args)


class ConfigError(MopeError):
    """A configuration value is unknown or out of range."""


class PreferenceError(MopeError):
    """A preference vector is malformed."""


class EnvironmentError_(MopeError):
    """An environment id is unknown or the environment is not supported."""


class CheckpointError(MopeError):
    """A checkpoint cannot be read, is unsafe, or does not fit."""


class DemonstrationError(MopeError):
    """Demonstrations (a scripted policy, a callable or a file of episodes) cannot be collected, read or used."""


def suggest(name: str, choices: Iterable[str]) -> str:
    """Return ``" (did you mean 'x'?)"`` for the closest choice, or an empty string."""
    match = difflib.get_close_matches(name, list(choices), n=1, cutoff=0.5)
    return f" (did you mean '{match[0]}'?)" if match else ""
