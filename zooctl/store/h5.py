"""HDF5 helpers the store's file formats share: reading a file with clear errors, and its layout as JSON."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from ..errors import StoreError

T = TypeVar("T")


def read_h5(path: Path, what: str, hint: str, read: Callable[[Any], T]) -> T:
    """``read(h5py.File)`` on ``path`` opened for reading.

    A file that cannot be opened, or whose content ``read`` trips over (a missing group, a bad
    dtype), is one `StoreError` naming ``what`` ("asset file") and the ``hint``; a `StoreError`
    that ``read`` raises itself passes through as it is."""
    import h5py

    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise StoreError(f"{what} {path} is unreadable: {exc}", hint=hint) from None
    with f:
        try:
            return read(f)
        except (OSError, KeyError, ValueError, TypeError, AttributeError) as exc:  # damaged inside
            raise StoreError(f"{what} {path} is damaged: {type(exc).__name__}: {exc}", hint=hint) from None


def describe_h5(path: Path) -> dict[str, Any]:
    """The file's layout as JSON: groups, datasets (dtype, shape, attributes, compression) and
    attributes; what the schema tests validate (``schemas/*_h5.schema.json``, asset_views).

    A dataset's dtype is numpy's dtype string, "str" for variable-length strings and "vlen" for
    other variable-length data (JPEG bytes)."""
    import h5py

    def attrs(obj: Any) -> dict[str, Any]:
        return {
            k: (v.item() if isinstance(v, np.generic) else v.decode() if isinstance(v, bytes) else v)
            for k, v in obj.attrs.items()
        }

    def dtype(ds: Any) -> str:
        if h5py.check_string_dtype(ds.dtype) is not None:
            return "str"
        return "vlen" if h5py.check_vlen_dtype(ds.dtype) is not None else ds.dtype.str

    def walk(g: Any) -> dict[str, Any]:
        node: dict[str, Any] = {"attrs": attrs(g), "groups": {}, "datasets": {}}
        for key, obj in g.items():
            if isinstance(obj, h5py.Group):
                node["groups"][key] = walk(obj)
            else:
                node["datasets"][key] = {
                    "dtype": dtype(obj),
                    "shape": list(obj.shape),
                    "attrs": attrs(obj),
                    "compression": obj.compression,
                }
        return node

    with h5py.File(path, "r") as f:
        return walk(f)
