"""Fit records: ``<store>/fits/<name>/``, one folder per fit, written atomically under the lock.

Layout (``schemas/fit_record.schema.json`` describes ``record.json``)::

    fits/<name>/record.json    what `fits list` / `fits show` read: status, template, outputs, metrics
    fits/<name>/state.pt       the resumable optimisation state (`zooctl fit --resume`)
    fits/<name>/character.h5   the fitted character (a RiggedAsset) that `fits export` re-exports
    fits/<name>/config.json    the full configuration of the run

and, unless ``--out`` sent them elsewhere, the outputs (``<name>.usd``, ``<name>.glb``,
``overlay.mp4``, ``loss.png``, ``fit.json``). A fit exists once its ``record.json`` exists.
"""

from __future__ import annotations

import ctypes
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

from ..asset import RiggedAsset
from ..errors import NotFoundError, StoreError
from ..names import check_name
from .fs import fsync_dir, read_regular, store_lock, write_bytes_atomic, write_json_atomic, writing
from .indexed import NamedStore

RECORD_VERSION = 1


class FitStore(NamedStore):
    """The fits of one store root."""

    noun, article, place, list_cmd = "fit", "a", "the store", "zooctl fits list"
    folder = "fits"

    def path(self, name: str) -> Path:
        return self.dir / check_name(name, "fit name")

    def record_path(self, name: str) -> Path:
        return self.path(name) / "record.json"

    def state_path(self, name: str) -> Path:
        return self.path(name) / "state.pt"

    def character_path(self, name: str) -> Path:
        return self.path(name) / "character.h5"

    def exists(self, name: str) -> bool:
        return self.record_path(name).is_file()

    def names(self) -> list[str]:
        if not self.dir.is_dir():
            return []
        return sorted(p.name for p in self.dir.iterdir() if (p / "record.json").is_file())

    def get(self, name: str) -> dict[str, Any]:
        p = self.record_path(name)
        try:
            record = json.loads(read_regular(p))  # a FIFO here would block `fits show`
        except FileNotFoundError:
            raise self._not_found(name) from None
        except OSError as exc:
            raise StoreError(f"the record of fit {name!r} is unreadable: {exc.strerror}") from None
        except (ValueError, RecursionError) as exc:  # UnicodeDecodeError is a ValueError
            record, problem = None, f"not JSON ({str(exc)[:80]})"
        else:
            problem = record_problem(name, record)
        if problem:
            raise StoreError(
                f"the record of fit {name!r} is damaged: {problem}",
                hint=f"remove it with `zooctl fits rm {name}`, then fit the video again",
            )
        return record

    def records(self) -> tuple[list[dict[str, Any]], dict[str, str]]:
        """Every readable fit record, and {name: why} for the fits whose record is not."""
        out, skipped = [], {}
        for n in self.names():
            try:
                out.append(self.get(n))
            except StoreError as exc:
                skipped[n] = exc.message
        return out, skipped

    def list(self) -> list[dict[str, Any]]:
        return self.records()[0]

    def save_record(self, name: str, record: dict[str, Any]) -> None:
        record = dict(record, schema_version=RECORD_VERSION, name=name)
        with store_lock(self.root):
            write_json_atomic(self.record_path(name), record)

    def save_state(self, name: str, state: dict[str, Any]) -> None:
        import io

        import torch

        buf = io.BytesIO()
        torch.save(_plain(state), buf)
        with store_lock(self.root):
            write_bytes_atomic(self.state_path(name), buf.getvalue())

    def load_state(self, name: str) -> dict[str, Any]:
        import torch

        p = self.state_path(name)
        if not p.is_file():
            raise NotFoundError(
                f"fit {name!r} has no saved state to resume", hint="start it again without --resume"
            )
        try:
            # weights_only: tensors, numbers, strings and containers only, never code (a state
            # file is as untrusted as any file in a store someone else may have written).
            state = torch.load(p, map_location="cpu", weights_only=True)
        except Exception as exc:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise StoreError(
                f"the saved state of fit {name!r} is unreadable or not plain data: {first}",
                hint="start it again without --resume",
            ) from None
        if not isinstance(state, dict):
            raise StoreError(
                f"the saved state of fit {name!r} is not a fit state (a {type(state).__name__})",
                hint="start it again without --resume",
            )
        return state

    def save_character(self, name: str, asset: RiggedAsset) -> None:
        from .asset_h5 import write_asset
        from .fs import publish, temp_path

        final = self.character_path(name)
        tmp = temp_path(final)
        try:
            write_asset(tmp, asset)
            with store_lock(self.root), writing(f"saving the character of fit {name!r}"):
                publish(tmp, final)
        finally:
            tmp.unlink(missing_ok=True)

    def character(self, name: str) -> RiggedAsset:
        from .asset_h5 import read_asset

        self.get(name)
        p = self.character_path(name)
        if not p.is_file():
            raise NotFoundError(
                f"fit {name!r} has no fitted character (it did not finish)",
                hint="resume it with `zooctl fit --resume`",
            )
        return read_asset(p)

    def staging(self, name: str) -> Path:
        """A private store root for a fit that will replace ``name`` (`replace_with`): inside this
        store's fits folder, so the swap is a rename on one filesystem, and hidden from `names`."""
        with writing(f"preparing to replace fit {name!r}"):
            self.dir.mkdir(parents=True, exist_ok=True)
            return Path(tempfile.mkdtemp(prefix=f".replacing-{check_name(name, 'fit name')}.", dir=self.dir))

    def replace_with(self, name: str, staged: Path, before_swap: Any = None) -> None:
        """Make the finished fit folder ``staged`` (inside `staging`'s folder) the fit ``name``.

        Under the lock, ``before_swap()`` runs first (publishing outputs that live outside the
        store), then the two folders are exchanged in one rename where the OS can, so a reader
        sees the old fit or the new one, never neither; the old folder is removed afterwards."""
        final = self.path(name)
        old: Path | None = None
        with store_lock(self.root), writing(f"replacing fit {name!r}"):
            if before_swap is not None:
                before_swap()
            if final.exists():
                if _exchange(staged, final):
                    old = staged
                else:
                    old = staged.with_name(staged.name + ".old")
                    os.replace(final, old)
                    os.replace(staged, final)
            else:
                os.replace(staged, final)
            fsync_dir(self.dir)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)

    def remove(self, name: str) -> None:
        with store_lock(self.root), writing(f"removing fit {name!r}"):
            if not self.exists(name):
                raise self._not_found(name)
            self.record_path(name).unlink()  # the fit is gone once its record is
        shutil.rmtree(self.path(name), ignore_errors=True)


_TYPES: dict[str, tuple[type, ...]] = {
    "status": (str,),
    "source": (str,),
    "template": (str,),
    "out": (str,),
    "frames": (int,),
    "image_size": (list,),
    "metrics": (dict,),
    "outputs": (dict,),
}


def record_problem(name: str, record: Any) -> str | None:
    """What makes ``record`` unusable as fit ``name``'s record (None: nothing): the fields that
    `fits list` and `fits show` read, checked for their types (schemas/fit_record.schema.json)."""
    if not isinstance(record, dict):
        return f"it holds a JSON {type(record).__name__}, not an object"
    if record.get("name") != name:
        return "it has no name" if "name" not in record else f"it names another fit ({record['name']!r})"
    for key, types in _TYPES.items():
        v = record.get(key)
        if v is not None and (not isinstance(v, types) or isinstance(v, bool)):
            return f"its {key!r} is a {type(v).__name__}"
    iou = (record.get("metrics") or {}).get("mask_iou")
    if iou is not None and (isinstance(iou, bool) or not isinstance(iou, (int, float))):
        return f"its mask IoU is a {type(iou).__name__}"
    return None


def _plain(obj: Any) -> Any:
    """``obj`` with numpy scalars and arrays as Python numbers and tensors: what
    ``torch.load(weights_only=True)`` reads back without allowing any class."""
    import numpy as np
    import torch

    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return torch.from_numpy(np.ascontiguousarray(obj))
    if isinstance(obj, dict):
        return {k: _plain(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return type(obj)(_plain(v) for v in obj)
    return obj


def rebase_paths(obj: Any, old: str, new: str) -> Any:
    """``obj`` (a record's JSON) with every string path under ``old`` moved under ``new``."""
    if isinstance(obj, str):
        return new + obj[len(old) :] if obj == old or obj.startswith(old + "/") else obj
    if isinstance(obj, dict):
        return {k: rebase_paths(v, old, new) for k, v in obj.items()}
    if isinstance(obj, list):
        return [rebase_paths(v, old, new) for v in obj]
    return obj


_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _exchange(a: Path, b: Path) -> bool:
    """Swap two paths atomically (Linux ``renameat2(RENAME_EXCHANGE)``); False where unsupported."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (22, 38, 95):  # EINVAL, ENOSYS, EOPNOTSUPP: this filesystem or kernel cannot
        return False
    raise OSError(err, os.strerror(err), str(b))
