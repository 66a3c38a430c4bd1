"""One instance of each embedder per process: loading its weights is the slow part of a small
`bank add` or search."""

from __future__ import annotations

from typing import Any

from ..embed.base import Embedder, get_embedder

_EMBEDDERS: dict[tuple[str, str, tuple], Embedder] = {}


def cached_embedder(name: str, device: str = "cpu", **options: Any) -> Embedder:
    """The embedder registered as ``name``, built on first use and kept for the process."""
    key = (name, device, tuple(sorted(options.items())))
    if key not in _EMBEDDERS:
        _EMBEDDERS[key] = get_embedder(name, device=device, **options)
    return _EMBEDDERS[key]
