"""Checkpoint files: atomic writes and safe reads.

A checkpoint is a ``torch.save`` of a dict holding only tensors, numbers, strings, lists and dicts. It always
carries ``format_version``, ``mope_version`` and the run's ``config``. It is read with
``torch.load(weights_only=True)``, so a file that smuggles in a pickled object (which could run code when
unpickled) is refused before anything in it runs.
"""

from __future__ import annotations

import errno
import os
import pickle
import shutil
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
    data = {"format_version": FORMAT_VERSION, "mope_version": mope_version(), **payload}
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        blocker = next((a for a in path.parents if a.exists() and not a.is_dir()), None)
        reason = f"'{blocker}' is a file, not a folder" if blocker else exc.strerror or str(exc)
        raise CheckpointError(f"cannot write checkpoint '{path}': folder '{path.parent}' is not writable ({reason})"
                              ) from None
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the file the permissions of an ordinary write
    try:
        with os.fdopen(fd, "wb") as f:
            torch.save(data, f)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        Path(tmp).unlink(missing_ok=True)
        cause = _write_failure(exc, path.parent)
        if cause is not None:
            raise CheckpointError(f"cannot write checkpoint '{path}': {cause}; any previous file there is unchanged"
                                  ) from None
        raise
    return path


def _write_failure(exc: BaseException, folder: Path) -> str | None:
    """Why a checkpoint write failed, if it failed for the file system: an ``OSError``, or the ``RuntimeError`` that
    torch's zip writer raises on top of one (a full disk ends ``torch.save`` with both); ``None`` otherwise."""
    seen: list[BaseException] = []
    e: BaseException | None = exc
    while e is not None and len(seen) < 5:
        seen.append(e)
        e = e.__context__
    os_error = next((e for e in seen if isinstance(e, OSError)), None)
    writer = isinstance(exc, RuntimeError) and any(k in str(exc) for k in ("inline_container", "PytorchStreamWriter",
                                                                           "file write failed"))
    if os_error is None and not writer:
        return None
    if (os_error is not None and os_error.errno in (errno.ENOSPC, errno.EDQUOT)) or _nearly_full(folder):
        return "the disk is full"
    return os_error.strerror or str(os_error) if os_error is not None else f"the write failed ({str(exc)[:120]})"


def _nearly_full(folder: Path) -> bool:
    try:
        return shutil.disk_usage(folder).free < 16 * 2**20
    except OSError:
        return False


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
    _check_archive(path)
    try:
        data = torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as exc:
        msg = str(exc).splitlines()[0] if str(exc) else "unsupported content"
        if "Unsupported operand" in str(exc):  # random bytes, an old-protocol pickle: no object, only unreadable
            raise CheckpointError(f"'{path}' is not a mope checkpoint: it is neither a torch archive nor a pickle of "
                                  "plain data (torch cannot read it); give a checkpoint written by mope") from None
        if "weights_only" in str(exc) or "Unsupported global" in str(exc) or "GLOBAL" in str(exc):
            raise CheckpointError(
                f"checkpoint '{path}' was refused: it contains pickled objects that are not plain data and could run "
                "code when loaded; only load checkpoints written by mope"
            ) from None
        raise CheckpointError(f"checkpoint '{path}' is corrupt: {msg}") from None
    except Exception as exc:  # noqa: BLE001 - a damaged file can fail anywhere inside torch's reader
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise CheckpointError(f"checkpoint '{path}' is truncated or corrupt ({first[:200]})") from None
    if not isinstance(data, dict) or "format_version" not in data or "config" not in data:
        raise CheckpointError(f"'{path}' is not a mope checkpoint (no format_version/config)")
    if data["format_version"] != FORMAT_VERSION:
        raise CheckpointError(
            f"checkpoint '{path}' has format version {data['format_version']}; this mope reads version {FORMAT_VERSION}"
        )
    return data


def _check_archive(path: Path) -> None:
    """Verify the CRC-32 of every member of a zip checkpoint (torch's reader does not), before unpickling.

    Files that are not zip archives (torch's legacy format) are left to ``torch.load``.
    """
    try:
        if not zipfile.is_zipfile(path):
            with open(path, "rb") as f:
                starts_as_zip = f.read(4) == b"PK\x03\x04"
            if starts_as_zip:  # a zip checkpoint whose end (the central directory) is missing
                raise CheckpointError(f"checkpoint '{path}' is truncated or corrupt (the archive is incomplete)")
            return
        with zipfile.ZipFile(path) as archive:
            bad = archive.testzip()
    except CheckpointError:
        raise
    except Exception as exc:  # noqa: BLE001 - BadZipFile, OSError, UnicodeDecodeError, NotImplementedError, ...
        if isinstance(exc, OSError) and not isinstance(exc, zipfile.BadZipFile):
            first = "the archive is incomplete"
        else:
            first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise CheckpointError(f"checkpoint '{path}' is truncated or corrupt ({first[:200]})") from None
    if bad is not None:
        raise CheckpointError(f"checkpoint '{path}' is corrupt (checksum mismatch in '{bad}')")


def check_compatible(data: dict[str, Any], path: str | Path, env_id: str | None, n_objectives: int,
                     n_actions: int, obs_shape: tuple[int, ...] | None = None, same_env: bool = True) -> None:
    """Raise :class:`CheckpointError` if a loaded checkpoint does not fit the environment it is loaded into.

    Args:
        data: What :func:`load_checkpoint` returned.
        path: The checkpoint's path, for the message.
        env_id: Id of the environment it is loaded into (``None``: not known, not compared).
        n_objectives: Its number of objectives.
        n_actions: Its number of actions.
        obs_shape: Its observation shape (``None``: not compared).
        same_env: Also refuse another environment id with the same shapes.
    """
    config = data.get("config") or {}
    saved = data.get("env") or {}
    saved_id = config.get("env_id")
    saved_m, saved_a, saved_shape = saved.get("n_objectives"), saved.get("n_actions"), saved.get("obs_shape")
    kinds = []
    if saved_m is not None and int(saved_m) != n_objectives:
        kinds.append("another number of objectives")
    if saved_a is not None and int(saved_a) != n_actions:
        kinds.append("another number of actions")
    if saved_shape is not None and obs_shape is not None and tuple(saved_shape) != tuple(obs_shape):
        kinds.append("another observation shape")
    if same_env and saved_id is not None and env_id is not None and saved_id != env_id:
        kinds.insert(0, "another environment")
    if not kinds:
        return

    def describe(m: Any, a: Any, shape: Any) -> str:
        m, a, shape = ("?" if m is None else m), ("?" if a is None else a), ("?" if shape is None else tuple(shape))
        return f"{m} objectives, {a} actions, observations {shape}"

    raise CheckpointError(
        f"checkpoint '{path}' does not fit ({', '.join(kinds)}): it was trained on '{saved_id}' "
        f"({describe(saved_m, saved_a, saved_shape)}) but the environment given is '{env_id or '?'}' "
        f"({describe(n_objectives, n_actions, obs_shape)}); load it with '{saved_id}'"
    )
