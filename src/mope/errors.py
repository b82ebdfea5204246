"""Errors that mope raises for bad input.

Every check at a boundary (CLI flag, API argument, config file, checkpoint) raises a subclass of
:class:`MopeError` with one line that names the bad value and what is allowed. The CLI turns these into
``error: ...`` and exit code 2, without a traceback.
"""

from __future__ import annotations

import difflib
import errno
import reprlib
from collections.abc import Iterable
from typing import Any

#: The longest message an error carries: with ``error: `` in front, every error line stays under 400 characters.
#: Values that come from the user (a config value, a path, a file's key) are shown cut short where the message is
#: made (:func:`short_repr`), so errors about them stay under 300; the cap is for what no check foresaw.
MAX_MESSAGE = 390
_ELLIPSIS = " … "


def one_line(text: str, limit: int = MAX_MESSAGE) -> str:
    """Collapse ``text`` to one line (runs of whitespace, newlines included, become one space) of at most ``limit``
    characters: a longer one keeps its start and its end (where the fix usually is) around an ellipsis."""
    text = str(text)
    if len(text) > 8 * limit:  # never split a huge text whole: only its two ends can be shown
        text = text[:4 * limit] + " " + text[-4 * limit:]
    text = " ".join(text.split())
    if len(text) <= limit:
        return text
    tail = limit // 3
    head = limit - tail - len(_ELLIPSIS)
    return text[:head].rstrip() + _ELLIPSIS + text[-tail:].lstrip()


_SHORT = reprlib.Repr()
_SHORT.maxlevel, _SHORT.maxlist, _SHORT.maxtuple, _SHORT.maxdict = 2, 8, 8, 6
_SHORT.maxstring, _SHORT.maxother, _SHORT.maxlong = 60, 60, 40


def short_repr(value: Any, limit: int = 80) -> str:
    """``repr(value)`` cut short: two levels, a few items, at most ``limit`` characters, in time that does not grow
    with the value (a YAML alias bomb's nested lists are never formatted whole)."""
    text = _SHORT.repr(value)
    return text if len(text) <= limit else text[:limit - 4] + " ..."


def is_disk_full(exc: BaseException) -> bool:
    """Whether ``exc`` is a write that failed because the file system is full (or over its quota)."""
    return isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT)


class MopeError(ValueError):
    """Base class of every user-facing error in mope.

    The message is always one line: text from elsewhere (a YAML parser, torch, the OS) that spans several lines
    is collapsed, so the CLI can print it as a single ``error: ...`` line.
    """

    def __init__(self, *args: object) -> None:
        if len(args) == 1 and isinstance(args[0], str):
            args = (one_line(args[0]),)
        super().__init__(*args)

    def __str__(self) -> str:  # one capped line, whatever was passed in
        return one_line(super().__str__())


class ConfigError(MopeError):
    """A configuration value is unknown or out of range."""


class PreferenceError(MopeError):
    """A preference vector is malformed."""


class EnvironmentError_(MopeError):
    """An environment id is unknown or the environment is not supported."""


class RunFolderError(MopeError):
    """The output folder is unusable (exists with results, or is not writable)."""


class CheckpointError(MopeError):
    """A checkpoint cannot be read, is unsafe, or does not fit."""


class DemonstrationError(MopeError):
    """Demonstrations (a scripted policy, a callable or a file of episodes) cannot be collected, read or used."""


def suggest(name: str, choices: Iterable[str]) -> str:
    """Return ``" (did you mean 'x'?)"`` for the closest choice, or an empty string."""
    match = difflib.get_close_matches(name, list(choices), n=1, cutoff=0.5)
    return f" (did you mean '{match[0]}'?)" if match else ""
