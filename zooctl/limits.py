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

from .errors import InputError


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
