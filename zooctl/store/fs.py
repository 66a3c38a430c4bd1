"""Crash-safe file primitives every store class uses: one writers' lock and atomic replace.

Readers never lock: every file a reader can see is complete, because writers only ever publish a
file by ``os.replace`` of a fully written and fsynced temporary in the same directory.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import re
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from ..errors import StoreError

LOCK_TIMEOUT_S = float(os.environ.get("ZOOCTL_LOCK_TIMEOUT", "120"))


@contextlib.contextmanager
def store_lock(root: Path, timeout: float = LOCK_TIMEOUT_S) -> Iterator[None]:
    """Hold the store's exclusive writers' lock (``root/.lock``, ``flock``).

    The kernel drops an flock when its holder dies, so a killed writer never leaves a stale lock.
    """
    root.mkdir(parents=True, exist_ok=True)
    fd = os.open(root / ".lock", os.O_RDWR | os.O_CREAT, 0o644)
    try:
        deadline = time.monotonic() + timeout
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if time.monotonic() > deadline:
                    raise StoreError(
                        f"the store {root} is locked by another zooctl process",
                        hint="wait for it to finish, or raise ZOOCTL_LOCK_TIMEOUT (seconds)",
                    ) from None
                time.sleep(0.02)
        yield
    finally:
        os.close(fd)  # closing releases the flock


def fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def temp_path(final: Path) -> Path:
    """A fresh temporary path beside ``final`` (same filesystem, so os.replace is atomic)."""
    final.parent.mkdir(parents=True, exist_ok=True)
    # The writer's pid is in the name so cleanup can tell a dead writer's leftovers from live work.
    fd, name = tempfile.mkstemp(prefix=f".{final.name}.{os.getpid()}.", suffix=".tmp", dir=final.parent)
    os.close(fd)
    return Path(name)


def publish(tmp: Path, final: Path) -> None:
    """fsync ``tmp`` and atomically move it to ``final``, then fsync the directory."""
    fd = os.open(tmp, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, final)
    fsync_dir(final.parent)


def write_bytes_atomic(final: Path, data: bytes) -> None:
    tmp = temp_path(final)
    try:
        tmp.write_bytes(data)
        publish(tmp, final)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_json_atomic(final: Path, obj: Any) -> None:
    # No indent: json's C encoder only runs without one (10x faster on a 1,000-asset index).
    write_bytes_atomic(final, (json.dumps(obj, sort_keys=True, separators=(",", ":")) + "\n").encode())


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_temps(directory: Path) -> int:
    """Delete temporaries whose writer process is gone. Returns how many were removed."""
    n = 0
    if not directory.is_dir():
        return 0
    for p in directory.glob(".*.tmp*"):
        m = re.search(r"\.(\d+)\.[^.]+\.tmp", p.name)
        if m and _pid_alive(int(m.group(1))):
            continue
        with contextlib.suppress(FileNotFoundError):
            p.unlink()
            n += 1
    return n
