"""Checkpoint files: atomic writes and safe reads.

A checkpoint is a ``torch.save`` of a dict holding only tensors, numbers, strings, lists and dicts. It always
carries ``format_version``, ``mope_version`` and the run's ``config``. It is read with
``torch.load(weights_only=True)``, so a file that smuggles in a pickled object (which could run code when
unpickled) is refused before anything in it runs.
"""

from __future__ import annotations

import os
import pickle
import tempfile
import zipfile
from pathlib import Path
from typing import Any

import torch

from mope.errors import CheckpointError

FORMAT_VERSION = 1


def mope_version() -> str:
    """Installed version of mope."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("mope")
    except PackageNotFoundError:  # running from a source tree
        return "0+unknown"


def save_checkpoint(path: str | Path, payload: dict[str, Any]) -> Path:
    """Write ``payload`` to ``path`` atomically: a temporary file in the same folder, then a rename.

    A crash during the write leaves any previous file at ``path`` intact.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    data = {"format_version": FORMAT_VERSION, "mope_version": mope_version(), **payload}
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the file the permissions of an ordinary write
    try:
        with os.fdopen(fd, "wb") as f:
            torch.save(data, f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def load_checkpoint(path: str | Path) -> dict[str, Any]:
    """Read a checkpoint safely.

    Raises:
        CheckpointError: if the file is missing, truncated or corrupt, carries objects that are not plain data
            (refused unexecuted), or is not a mope checkpoint of a known format.
    """
    path = Path(path)
    if path.is_dir():
        raise CheckpointError(f"'{path}' is a folder; give a checkpoint file or a run folder")
    if not path.is_file():
        raise CheckpointError(f"checkpoint '{path}' does not exist")
    try:
        data = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as exc:
        msg = str(exc).splitlines()[0] if str(exc) else "unsupported content"
        if "weights_only" in str(exc) or "Unsupported global" in str(exc) or "GLOBAL" in str(exc):
            raise CheckpointError(
                f"checkpoint '{path}' was refused: it contains pickled objects that are not plain data and could run "
                "code when loaded; only load checkpoints written by mope"
            ) from None
        raise CheckpointError(f"checkpoint '{path}' is corrupt: {msg}") from None
    except (RuntimeError, EOFError, zipfile.BadZipFile, OSError, ValueError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise CheckpointError(f"checkpoint '{path}' is truncated or corrupt ({first})") from None
    if not isinstance(data, dict) or "format_version" not in data or "config" not in data:
        raise CheckpointError(f"'{path}' is not a mope checkpoint (no format_version/config)")
    if data["format_version"] != FORMAT_VERSION:
        raise CheckpointError(
            f"checkpoint '{path}' has format version {data['format_version']}; this mope reads version {FORMAT_VERSION}"
        )
    return data
