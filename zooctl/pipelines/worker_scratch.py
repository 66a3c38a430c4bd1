"""A batch worker's private scratch folder, and the removal of those whose worker died.

A worker killed outright (SIGKILL, the out-of-memory killer, a Ray node lost, a task Ray
cancels by force) cannot remove its folder, and a video it decoded there can be large. So each
worker holds an ``flock`` on a file in its folder for as long as it lives (the kernel drops the
lock when the process dies, however it dies), and every new task on the machine first removes
the folders whose lock nobody holds.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import secrets
import shutil
import tempfile
import time
from pathlib import Path

PREFIX = "zooctl-fit-"
_OWNER = ".owner"
# A folder with no owner file: its worker died between making it and locking it (a few
# microseconds), or it is being made now. Left alone until it is this old.
_UNOWNED_GRACE_S = 3600.0


def scratch_path(name: str, root: Path | None = None) -> Path:
    """A new scratch folder's path (not made yet) for the task ``name``, in ``root`` (default
    the system's temporary folder)."""
    return Path(root or tempfile.gettempdir()) / f"{PREFIX}{name}-{secrets.token_hex(8)}"


def claim(folder: Path) -> int:
    """Make ``folder`` (private to this user) and lock it as this process's: returns the lock's
    descriptor, to `release` once the folder is removed. The owner file appears already locked
    (locked under another name, then renamed), so a sweep never takes a live folder for a dead one."""
    folder.mkdir(mode=0o700)
    tmp = folder / f"{_OWNER}-{os.getpid()}"
    fd = os.open(tmp, os.O_CREAT | os.O_WRONLY | os.O_NOFOLLOW, 0o600)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        os.replace(tmp, folder / _OWNER)
    except BaseException:
        os.close(fd)
        raise
    return fd


def release(fd: int | None) -> None:
    """Let go of a folder's lock (after removing the folder)."""
    if fd is not None:
        with contextlib.suppress(OSError):
            os.close(fd)


def sweep_orphans(root: Path | None = None, now: float | None = None) -> list[Path]:
    """Remove the scratch folders in ``root`` (default the system's temporary folder) whose
    worker is gone: their owner file's lock is free, or they have none and are older than an hour.
    Only this user's folders; anything unreadable is left alone. Returns what was removed."""
    root = Path(root or tempfile.gettempdir())
    now = time.time() if now is None else now
    removed = []
    try:
        entries = [e for e in os.scandir(root) if e.name.startswith(PREFIX)]
    except OSError:
        return removed
    for e in entries:
        try:
            if not e.is_dir(follow_symlinks=False) or e.stat(follow_symlinks=False).st_uid != os.getuid():
                continue
            fd = os.open(Path(e.path) / _OWNER, os.O_RDONLY | os.O_NOFOLLOW)
        except FileNotFoundError:
            with contextlib.suppress(OSError):
                if now - e.stat(follow_symlinks=False).st_mtime > _UNOWNED_GRACE_S:
                    shutil.rmtree(e.path, ignore_errors=True)
                    removed.append(Path(e.path))
            continue
        except OSError:
            continue
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:  # held: its worker lives
            os.close(fd)
            continue
        try:
            shutil.rmtree(e.path, ignore_errors=True)
            removed.append(Path(e.path))
        finally:
            os.close(fd)
    return removed
