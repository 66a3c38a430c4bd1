"""Resource limits of imports: a small file must not make zooctl allocate gigabytes.

A 60 KB glTF with one keyframe at t = 1e5 s asks for a three-million-frame clip; an accessor
without a bufferView can claim a billion zero elements. Importers check these limits *before*
allocating and raise an `InputError` that names the limit and the `bank add` option raising it.
The defaults are far above real assets (the shared animals: under 1,000 frames, 60 joints).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, replace

from .errors import InputError, ZooctlError


@dataclass(frozen=True)
class ImportLimits:
    max_clip_seconds: float = 600.0  # one clip, first to last keyframe
    max_frames: int = 100_000  # all clips of one asset together, after resampling
    max_vertices: int = 500_000  # all meshes together: posing 8 influences takes ~2 kB per vertex
    max_elements: int = 5_000_000  # one accessor; frames x joints of all clips


DEFAULT = ImportLimits()
_current: ContextVar[ImportLimits] = ContextVar("zooctl_import_limits", default=DEFAULT)

OPTION = {
    "max_clip_seconds": "--max-clip-seconds",
    "max_frames": "--max-frames",
    "max_vertices": "--max-vertices",
    "max_elements": "--max-elements",
}


def current() -> ImportLimits:
    """The limits in force (the defaults unless a caller is inside `import_limits`)."""
    return _current.get()


def limits_with(**changes: float | int | None) -> ImportLimits:
    """The current limits with ``changes`` applied (``None`` keeps a value); bad values are an
    `InputError` naming the option."""
    for key, value in changes.items():
        if key not in OPTION:
            raise TypeError(f"unknown import limit {key!r}")
        if value is not None and not value > 0:
            raise InputError(f"{OPTION[key]} must be positive, got {value}")
    return replace(current(), **{k: v for k, v in changes.items() if v is not None})


@contextmanager
def import_limits(**changes: float | int | None) -> Iterator[ImportLimits]:
    """Raise (or lower) limits for the imports in this block; ``None`` keeps a limit's value."""
    lim = limits_with(**changes)
    token = _current.set(lim)
    try:
        yield lim
    finally:
        _current.reset(token)


def check(what: str, value: float, key: str, unit: str = "", factor: float = 1) -> None:
    """Raise an `InputError` when ``value`` is over ``factor`` times limit ``key`` (NaN counts as
    over): ``what`` says what is too big, the hint names the `bank add` option that allows it."""
    lim = getattr(current(), key) * factor
    if not value <= lim:
        raise InputError(
            f"{what} {_num(value)}{unit}, over the import limit of {_num(lim)}{unit}",
            hint=f"if the file is what you meant, raise the limit with `zooctl bank add {OPTION[key]} N`",
        )


def _num(v: float) -> str:
    return f"{v:,.0f}" if math.isfinite(v) and v == int(v) else f"{v:,g}"


# -- reads: what one file may make zooctl read or allocate --------------------------------------
#
# A sparse file claims gigabytes it does not hold, and an HDF5 dataset declares any shape in a few
# bytes; readers check these limits against the sizes a file declares *before* reading it, at the
# size the read allocates. A stored video is read a few frames at a time (its masks whole), so the
# array limit bounds one read, not a video's length; the defaults are above real data and keep a
# crafted file's peak under 2 GB.


@dataclass(frozen=True)
class ReadLimits:
    max_file_mb: float = 512.0  # one input file read whole: a model, a glTF buffer or image
    max_json_mb: float = 64.0  # one JSON text: a store index, card or record, a config, glTF JSON
    max_array_mb: float = 1024.0  # the arrays one read of a stored HDF5 file allocates, as declared


READ_ENV = {
    "max_file_mb": "ZOOCTL_MAX_FILE_MB",
    "max_json_mb": "ZOOCTL_MAX_JSON_MB",
    "max_array_mb": "ZOOCTL_MAX_ARRAY_MB",
}


def read_limits() -> ReadLimits:
    """The read limits in force: the defaults, each replaced by its environment variable when set."""
    import os

    values = {}
    for key, var in READ_ENV.items():
        text = os.environ.get(var, "").strip()
        if not text:
            continue
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not (math.isfinite(value) and value > 0):
            raise InputError(f"{var}={text!r} is not a positive number of megabytes", hint=f"unset {var}")
        values[key] = value
    return ReadLimits(**values)


def max_read_bytes(key: str) -> int:
    """Read limit ``key`` of `ReadLimits` in bytes."""
    return int(getattr(read_limits(), key) * 2**20)


def check_read(what: str, nbytes: float, key: str, error: type[ZooctlError] | None = None) -> None:
    """Raise ``error`` (default `InputError`) when ``nbytes`` is over read limit ``key``: ``what``
    says what is that big ("the asset file x.h5 declares arrays of"); the hint names the variable
    that raises the limit."""
    lim = max_read_bytes(key)
    if not nbytes <= lim:
        err: type[ZooctlError] = InputError if error is None else error
        raise err(
            f"{what} {mb_text(nbytes)}, over the read limit of {mb_text(lim)}", hint=read_hint(key, nbytes)
        )


def read_hint(key: str, nbytes: float) -> str:
    """What to do about a file over read limit ``key``: the variable, set to what it needs."""
    need = math.ceil(nbytes / 2**20) if math.isfinite(nbytes) else "N"
    return f"if the file is what you meant, raise the limit: {READ_ENV[key]}={need}"


def mb_text(nbytes: float) -> str:
    if not math.isfinite(nbytes):
        return f"{nbytes} bytes"
    return f"{nbytes / 2**20:,.1f} MB" if nbytes >= 2**20 else f"{nbytes:,.0f} bytes"
