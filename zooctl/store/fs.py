"""Crash-safe file primitives every store class uses: one writers' lock and atomic replace.

Readers never lock: every file a reader can see is complete, because writers only ever publish a
file by ``os.replace`` of a fully written and fsynced temporary in the same directory.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import re
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from ..errors import NoSpaceError, ReadOnlyStoreError, StoreError, UsageError

_NO_SPACE = {errno.ENOSPC, errno.EFBIG, errno.EDQUOT}
_READ_ONLY = {errno.EACCES, errno.EPERM, errno.EROFS}


def _umask() -> int:
    m = os.umask(0)
    os.umask(m)
    return m


_UMASK = _umask()


def _env_timeout() -> float:
    try:
        return float(os.environ.get("ZOOCTL_LOCK_TIMEOUT", "120"))
    except ValueError:
        return 120.0


# How long a writer waits for the lock: ZOOCTL_LOCK_TIMEOUT, or the CLI's --wait.
LOCK_TIMEOUT_S = _env_timeout()
# Called once with a description of the holder when a writer starts waiting (the CLI prints it).
on_lock_wait: Callable[[str], None] | None = None


def set_lock_timeout(seconds: float) -> None:
    global LOCK_TIMEOUT_S
    LOCK_TIMEOUT_S = check_wait(seconds, "--wait")


def check_wait(seconds: float, source: str) -> float:
    """``seconds`` as a lock wait: a finite number >= 0 (NaN or infinity would wait forever)."""
    import math

    if not (math.isfinite(seconds) and seconds >= 0):
        raise UsageError(
            f"{source}{' ' if source.startswith('-') else '='}{seconds:g} is not a number of seconds to wait",
            hint=f"give {source} a finite number of seconds, 0 or more (the default is 120)",
        )
    return float(seconds)


def os_error(exc: OSError, what: str) -> StoreError:
    """A store-level error for a failed filesystem call: read-only and full disks get their own
    classes (callers that only cache, like `bank search`, skip those), anything else says what failed."""
    if exc.errno in _NO_SPACE:
        return NoSpaceError(
            f"no space left on device / file too large while {what}: {exc.strerror}",
            hint="free disk space (or raise the file-size limit) and run it again; nothing was changed",
        )
    if exc.errno in _READ_ONLY:
        return ReadOnlyStoreError(
            f"the store is read-only: cannot write while {what} ({exc.strerror}: {exc.filename})",
            hint="use a writable --store, or ask for write permission on it",
        )
    return StoreError(f"{what} failed: {exc.strerror or exc} ({exc.filename or ''})")


@contextlib.contextmanager
def writing(what: str) -> Iterator[None]:
    """Turn OSErrors of the enclosed store writes into one clear `StoreError`."""
    try:
        yield
    except OSError as exc:
        raise os_error(exc, what) from None


def read_regular(path: Path) -> bytes:
    """A store JSON file's bytes; something else at ``path`` (a FIFO, a device) or a file over the
    JSON read limit is an OSError, not a hang or gigabytes read (`zooctl.files.read_regular`)."""
    from ..files import read_regular as read

    return read(path, "max_json_mb")


def lock_holder(root: Path) -> str:
    """Who holds the lock, as its holder wrote it (pid, command, since), or a generic phrase."""
    try:
        info = json.loads(read_regular(Path(root) / ".lock") or b"{}")
        return f"pid {int(info['pid'])} (`{info['command']}`, since {info['since']})"
    except (OSError, ValueError, KeyError, TypeError):
        return "another zooctl process"


@contextlib.contextmanager
def store_lock(root: Path, timeout: float | None = None) -> Iterator[None]:
    """Hold the store's exclusive writers' lock (``root/.lock``, ``flock``).

    The kernel drops an flock when its holder dies, so a killed writer never leaves a stale lock.
    The holder writes its pid and command into the file (schemas/store_lock.schema.json), so a
    waiting writer can say whom it waits for.
    """
    timeout = check_wait(LOCK_TIMEOUT_S, "ZOOCTL_LOCK_TIMEOUT") if timeout is None else timeout
    with writing(f"opening the store lock {root / '.lock'}"):
        root.mkdir(parents=True, exist_ok=True)
        fd = _open_lock(root / ".lock")
    try:
        deadline = time.monotonic() + timeout
        told = False
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if not told and on_lock_wait is not None:
                    on_lock_wait(lock_holder(root))
                told = True
                if time.monotonic() > deadline:
                    raise StoreError(
                        f"the store {root} is locked by {lock_holder(root)}; gave up after {timeout:g} s",
                        hint="wait for it to finish, or wait longer with --wait SECONDS (or ZOOCTL_LOCK_TIMEOUT)",
                    ) from None
                time.sleep(0.05)
        _write_holder(fd)
        yield
    finally:
        os.close(fd)  # closing releases the flock


def _open_lock(path: Path) -> int:
    """The lock file's descriptor. Never through a symlink (its holder line would overwrite the
    link's target, wherever that is) and never a FIFO or device: such a store is refused."""
    import stat

    hint = f"remove {path} (zooctl makes a fresh lock file) and check who put it there"
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC, 0o644)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise StoreError(
                f"the store lock {path} is a symbolic link; zooctl does not write through it", hint=hint
            ) from None
        raise
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise StoreError(f"the store lock {path} is not a regular file", hint=hint)
    return fd


def _write_holder(fd: int) -> None:
    info = {
        "pid": os.getpid(),
        "command": " ".join(["zooctl", *sys.argv[1:]])[:300],
        "since": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    with contextlib.suppress(OSError):  # only a courtesy to waiters: a full disk must not stop us
        os.ftruncate(fd, 0)
        os.pwrite(fd, json.dumps(info).encode(), 0)


def fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def temp_path(final: Path) -> Path:
    """A fresh temporary path beside ``final`` (same filesystem, so os.replace is atomic)."""
    with writing(f"creating a temporary beside {final}"):
        final.parent.mkdir(parents=True, exist_ok=True)
        # The writer's pid is in the name so cleanup can tell a dead writer's leftovers from live work.
        fd, name = tempfile.mkstemp(prefix=f".{final.name}.{os.getpid()}.", suffix=".tmp", dir=final.parent)
    try:
        os.fchmod(fd, 0o666 & ~_UMASK)  # mkstemp makes 0600: published files get the usual mode
    finally:
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
    """Publish ``data`` at ``final``; on any failure (a full disk included) the temporary is
    removed and ``final`` is as it was."""
    tmp = temp_path(final)
    try:
        with writing(f"writing {final}"):
            tmp.write_bytes(data)
            publish(tmp, final)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def h5_image(fill: Callable[[Any], None], libver: str | None = None) -> bytes:
    """Build an HDF5 file in memory (``fill(h5py.File)``) and return its bytes.

    Written to disk with `write_bytes_atomic`, a full disk is one clean OSError from ``write``
    instead of a failure inside the HDF5 library (which can crash the process).
    """
    import io

    import h5py

    buf = io.BytesIO()
    with h5py.File(buf, "w", **({"libver": libver} if libver else {})) as f:
        fill(f)
    return buf.getvalue()


def json_bytes(obj: Any) -> bytes:
    """How the store writes JSON. No indent: json's C encoder only runs without one (BENCHMARKS.md,
    Asset bank)."""
    return (json.dumps(obj, sort_keys=True, separators=(",", ":")) + "\n").encode()


def write_json_atomic(final: Path, obj: Any) -> None:
    write_bytes_atomic(final, json_bytes(obj))


def pid_alive(pid: int) -> bool:
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
        if m and pid_alive(int(m.group(1))):
            continue
        with contextlib.suppress(FileNotFoundError):
            p.unlink()
            n += 1
    return n
