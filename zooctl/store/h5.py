"""HDF5 helpers the store's file formats share: reading a file with clear errors, and its layout as JSON."""

from __future__ import annotations

import math
import os
import stat
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from ..errors import StoreError
from ..files import kind_of
from ..limits import check_read

T = TypeVar("T")


def open_h5(path: Path, what: str, hint: str, parts: Iterable[str] | None = None) -> Any:
    """``path`` opened read-only with h5py, once it is known to be safe to read: a regular file
    (a FIFO would block the HDF5 library forever) whose datasets keep their data inside the file
    (no external or virtual storage, which could name any other file) and, of them, those under
    ``parts`` (names of datasets or groups, all of them when None: what the caller reads whole)
    declare no more than the array read limit. Anything else is one `StoreError` naming ``what``
    ("asset file") with ``hint``."""
    import h5py

    try:
        st = os.stat(path)
        if not stat.S_ISREG(st.st_mode):
            raise StoreError(f"{what} {path} is {kind_of(st.st_mode)}, not a regular file", hint=hint)
        f = h5py.File(path, "r")
    except OSError as exc:
        raise StoreError(f"{what} {path} is unreadable: {exc}", hint=hint) from None
    try:
        total = declared_bytes(f, path, what, parts)
        check_read(f"{what} {path} declares arrays of", total, "max_array_mb", StoreError)
    except StoreError:
        f.close()
        raise
    except (OSError, KeyError, ValueError, TypeError, RuntimeError) as exc:
        f.close()
        raise StoreError(f"{what} {path} is damaged: {type(exc).__name__}: {exc}", hint=hint) from None
    return f


def declared_bytes(f: Any, path: Path, what: str, parts: Iterable[str] | None = None) -> int:
    """The bytes the datasets under ``parts`` (None: all) of the open file ``f`` take once read,
    as their shapes and dtypes declare them (variable-length data counts its pointers). Refuses a
    dataset with its data in other files, wherever it is."""
    import h5py

    total = 0
    under = None if parts is None else tuple(parts)

    def visit(name: str, obj: Any) -> None:
        nonlocal total
        if isinstance(obj, h5py.Dataset):
            if obj.external or obj.is_virtual:
                raise StoreError(
                    f"{what} {path}: dataset {name} keeps its data in other files, which zooctl never writes",
                    hint="the file is not one zooctl wrote; remove it",
                )
            if under is None or any(name == p or name.startswith(p + "/") for p in under):
                total += math.prod(obj.shape or ()) * obj.dtype.itemsize

    f.visititems(visit)
    return total


def read_h5(
    path: Path, what: str, hint: str, read: Callable[[Any], T], parts: Iterable[str] | None = None
) -> T:
    """``read(h5py.File)`` on ``path`` opened for reading (`open_h5`: checked first; ``parts``:
    the datasets or groups ``read`` reads whole, None: all).

    A file that cannot be opened, or whose content ``read`` trips over (a missing group, a bad
    dtype), is one `StoreError` naming ``what`` ("asset file") and the ``hint``; a `StoreError`
    that ``read`` raises itself passes through as it is."""
    with open_h5(path, what, hint, parts) as f:
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
