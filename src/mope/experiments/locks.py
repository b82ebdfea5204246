"""Folder locks: one writer per run or sweep folder.

A lock is a file ``.mope.lock`` in the folder holding the writer's PID and host. It is created atomically
(``O_EXCL``); a second writer finds it and is refused with an error naming the holder. A lock whose process is
gone (a killed run on this host), or that still holds no PID after 10 s (its writer died while creating it), is
stale and is taken over. A lock held from another host is never taken over: delete it by hand once that run
is known to be dead.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import socket
import time
from pathlib import Path
from types import TracebackType

from mope.errors import MopeError

LOCK_NAME = ".mope.lock"
#: A lock file that still holds no readable PID after this many seconds was left by a writer killed at birth.
UNREADABLE_STALE_S = 10.0


class FolderLockedError(MopeError):
    """Another live process is writing the folder."""


def pid_alive(pid: int) -> bool:
    """Whether a process with this id exists on this machine (owned by anyone)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by someone else
        return True
    return True


class FolderLock:
    """Hold ``<folder>/.mope.lock`` for the duration of a ``with`` block (re-entrant within one process).

    Args:
        folder: The folder to lock (created if missing).
        what: How to name the folder in messages ("run folder", "sweep folder").
    """

    _held: dict[str, int] = {}

    def __init__(self, folder: str | Path, what: str = "folder") -> None:
        self.folder = Path(folder)
        self.what = what
        self.path = self.folder / LOCK_NAME

    def _holder(self) -> dict | None:
        try:
            return json.loads(self.path.read_text())
        except (OSError, ValueError):
            return None

    def _age(self) -> float:
        try:
            return time.time() - self.path.stat().st_mtime
        except OSError:
            return 0.0

    def acquire(self) -> None:
        try:
            key = str(self.path.resolve()) if self.folder.exists() else str(self.path.absolute())
            if FolderLock._held.get(key):
                FolderLock._held[key] += 1
                return
            if self.folder.exists() and not self.folder.is_dir():
                raise MopeError(f"output path '{self.folder}' exists and is not a folder")
            self.folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:  # not writable, a name longer than the file system allows, a loop of links
            how = "cannot be used" if exc.errno in (errno.ENAMETOOLONG, errno.ELOOP) else "is not writable"
            raise MopeError(f"{self.what} '{self.folder}' {how}: {exc.strerror or exc}") from None
        me = {"pid": os.getpid(), "host": socket.gethostname()}
        for _ in range(3):
            try:
                fd = os.open(self.path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
            except FileExistsError:
                holder = self._holder()
                if holder and holder.get("host") == me["host"] and not pid_alive(int(holder.get("pid", -1))):
                    with contextlib.suppress(FileNotFoundError):  # stale: its process is gone
                        self.path.unlink()
                    continue
                if holder is None and self._age() > UNREADABLE_STALE_S:  # its writer died before writing it
                    with contextlib.suppress(FileNotFoundError):
                        self.path.unlink()
                    continue
                if holder is None:  # being written right now: treat as held
                    holder = {"pid": "?", "host": "?"}
                raise FolderLockedError(
                    f"{self.what} '{self.folder}' is in use by process {holder.get('pid')} on {holder.get('host')}; "
                    f"wait for it to finish or stop it (a lock left by a killed process is taken over "
                    f"automatically)") from None
            except OSError as exc:
                raise MopeError(f"{self.what} '{self.folder}' is not writable: {exc.strerror or exc}") from None
            with os.fdopen(fd, "w") as f:
                json.dump(me, f)
            FolderLock._held[str(self.path.resolve())] = 1
            return
        raise FolderLockedError(f"{self.what} '{self.folder}' could not be locked")

    def release(self) -> None:
        try:
            key = str(self.path.resolve())
        except OSError:
            return
        count = FolderLock._held.get(key, 0)
        if count > 1:
            FolderLock._held[key] = count - 1
            return
        FolderLock._held.pop(key, None)
        holder = self._holder()
        if holder and holder.get("pid") == os.getpid():
            with contextlib.suppress(FileNotFoundError):
                self.path.unlink()

    def __enter__(self) -> FolderLock:
        self.acquire()
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.release()
