"""Reading a file that a user or the store names: regular files only, sizes checked first.

A FIFO or a socket blocks its reader forever, a device (``/dev/zero``, or a link to it) never
ends, and a sparse file claims gigabytes it does not hold. Files are opened without blocking,
checked with ``fstat`` (what was opened, after symlinks) and read only when they are regular and
within a read limit of `zooctl.limits`.
"""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

from .errors import InputError, ZooctlError
from .limits import check_read, max_read_bytes, mb_text, read_hint

_KINDS = {
    stat.S_IFIFO: "a FIFO (named pipe)",
    stat.S_IFSOCK: "a socket",
    stat.S_IFCHR: "a character device",
    stat.S_IFBLK: "a block device",
    stat.S_IFDIR: "a directory",
}


def kind_of(mode: int) -> str:
    """What a non-regular file is, in words ("a FIFO (named pipe)")."""
    return _KINDS.get(stat.S_IFMT(mode), "not a regular file")


class NotRegularFileError(OSError):
    """Something other than a regular file where a file's bytes are expected."""

    def __str__(self) -> str:
        return f"{self.filename} is {self.strerror}"


class TooLargeError(OSError):
    """A file over a read limit: ``strerror`` says by how much, `hint` what to do."""

    def __init__(self, size: int, limit: str, path: str | Path) -> None:
        cap = max_read_bytes(limit)
        super().__init__(
            errno.EOVERFLOW, f"{mb_text(size)}, over the read limit of {mb_text(cap)}", str(path)
        )
        self.hint = read_hint(limit, size)

    def __str__(self) -> str:
        return f"{self.filename} is {self.strerror}"


def read_regular(path: str | Path, limit: str = "max_json_mb") -> bytes:
    """The bytes of the regular file ``path``, at most read limit ``limit`` of them.

    Raises `NotRegularFileError` for a FIFO, socket, device or directory (never blocks on one),
    `TooLargeError` for a file over the limit (without reading it), and the usual OSErrors
    (FileNotFoundError, PermissionError)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as exc:  # a socket cannot be opened at all (ENXIO): say what it is
        mode = os.stat(path).st_mode if exc.errno == errno.ENXIO else stat.S_IFREG
        if not stat.S_ISREG(mode):
            raise NotRegularFileError(
                errno.EINVAL, f"{kind_of(mode)}, not a regular file", str(path)
            ) from None
        raise
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise NotRegularFileError(errno.EINVAL, f"{kind_of(st.st_mode)}, not a regular file", str(path))
        cap = max_read_bytes(limit)
        if st.st_size > cap:
            raise TooLargeError(st.st_size, limit, path)
        chunks, left = [], cap + 1  # a file that grows while read is cut at the limit, not followed
        while left > 0:
            block = os.read(fd, min(left, 1 << 24))
            if not block:
                break
            chunks.append(block)
            left -= len(block)
        if left <= 0:
            raise TooLargeError(cap + 1, limit, path)
        return b"".join(chunks)
    finally:
        os.close(fd)


def regular_size(
    path: str | Path, what: str, limit: str | None = None, error: type[ZooctlError] = InputError
) -> int:
    """The size of ``path`` (symlinks followed) when it is a regular file within read limit
    ``limit`` (None: any size); else one clear ``error`` naming ``what`` ("the video"). Opens
    nothing, so it never blocks; a missing file is ``FileNotFoundError``."""
    st = os.stat(path)
    if not stat.S_ISREG(st.st_mode):
        raise error(
            f"{what} {path} is {kind_of(st.st_mode)}, not a regular file",
            hint="give a regular file (a FIFO, a socket or a device cannot be read as one)",
        )
    if limit is not None:
        check_read(f"{what} {path} is", st.st_size, limit, error)
    return st.st_size


def read_input(
    path: str | Path, what: str, limit: str = "max_file_mb", error: type[ZooctlError] = InputError
) -> bytes:
    """`read_regular` for a file the user gave: every failure is one clear ``error`` naming
    ``what`` ("config file")."""
    try:
        return read_regular(path, limit)
    except FileNotFoundError:
        raise error(f"{what} {path} does not exist") from None
    except (NotRegularFileError, TooLargeError) as exc:
        hint = exc.hint if isinstance(exc, TooLargeError) else "give a regular file"
        raise error(f"{what} {path} is {exc.strerror}", hint=hint) from None
    except OSError as exc:
        raise error(f"{what} {path} is unreadable: {exc.strerror or exc}") from None
