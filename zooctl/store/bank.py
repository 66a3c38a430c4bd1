"""The asset bank: one HDF5 file per asset plus a JSON index, crash-safe.

Layout under the store root (JSON Schemas: ``schemas/bank_index.schema.json``,
``schemas/asset_card.schema.json`` and ``schemas/asset_h5.schema.json``)::

    bank/index.json          {"schema_version": 1, "assets": {name: summary}}  - what `bank list` reads
    bank/assets/<name>.h5    the asset itself (mesh, skeleton, skin, clips; later views, embeddings)
    bank/assets/<name>.json  the asset's card: summary + joint tree - what `bank show` reads

Why one file per asset: a killed writer can at worst leave a temporary file, never a damaged
bank, and replacing one asset rewrites only that asset. Every file is published by writing a
temporary beside it, fsync, ``os.replace``; the index is the single source of truth for which
assets exist, and it is replaced last, under the store's writers' lock. An asset file that the
index does not name (a writer killed between the two replaces) is invisible; `bank clean` keeps
and reports it, `bank repair` indexes it. A missing or damaged index is an error that names
`zooctl bank repair`, which rebuilds it from the asset files (`zooctl.store.indexed`).
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import StoreError
from ..names import check_name
from .fs import h5_image, read_regular, store_lock, write_bytes_atomic, write_json_atomic, writing
from .indexed import INDEX_VERSION, IndexedStore

if TYPE_CHECKING:  # numpy/h5py stay unimported for `bank list` and `bank show`
    from ..asset import RiggedAsset

__all__ = ["Bank", "INDEX_VERSION", "PENDING"]

# Index entry field of an asset whose retrieval views its `bank add` had still to render.
PENDING = "views_pending"


def _bbox_ok(b: Any) -> bool:
    return isinstance(b, list) and len(b) == 2 and all(isinstance(v, list) and len(v) == 3 for v in b)


class Bank(IndexedStore):
    """The asset bank of one store root."""

    noun, place, list_cmd = "asset", "the bank", "zooctl bank list"
    key, label, repair_cmd = "assets", "bank index", "zooctl bank repair"
    folder = "bank"
    required = {
        "name": str,
        "vertices": int,
        "faces": int,
        "joints": int,
        "clips": dict,
        "bbox": list,
        "tags": list,
        "license": str,
        "source": str,
        "has_texture": bool,
    }

    @property
    def files_dir(self) -> Path:
        return self.dir / "assets"

    assets_dir = files_dir

    def check_entry(self, name: str, entry: Any) -> str | None:
        problem = super().check_entry(name, entry)
        if problem:
            return problem
        if not _bbox_ok(entry["bbox"]):
            return "has a bad 'bbox'"
        v = entry.get("views")
        if v is not None and not (
            isinstance(v, dict)
            and isinstance(v.get("views_id"), str)
            and isinstance(v.get("embedders"), dict)
        ):
            return "has a bad 'views'"
        return None

    # -- reading (no lock: every visible file is complete) --------------------------------
    def card(self, name: str) -> dict[str, Any]:
        """Summary plus joint tree (what `bank show` prints), without opening the HDF5 file."""
        summary = self.summary(name)
        try:
            card = json.loads(read_regular(self.card_path(name)))
            if not isinstance(card, dict) or not isinstance(card.get("joint_names"), list):
                raise ValueError("not an asset card")
            if not isinstance(card.get("parents"), list) or not isinstance(card.get("skin_influences"), int):
                raise ValueError("not an asset card")
        except (OSError, ValueError, RecursionError) as exc:
            raise StoreError(
                f"the card of asset {name!r} is unreadable: {exc}",
                hint="run `zooctl bank repair` (it rewrites cards from the asset files)",
            ) from None
        card.update(summary)
        return card

    def asset_path(self, name: str) -> Path:
        return self.assets_dir / f"{name}.h5"

    def card_path(self, name: str) -> Path:
        return self.assets_dir / f"{name}.json"

    def get(self, name: str) -> RiggedAsset:
        """Load an asset and check it (`RiggedAsset.validate`, what every exporter and `bank add`
        require): a damaged file is one `StoreError` for every command that reads it. Raises
        `NotFoundError` when the bank has no such asset."""
        from ..errors import InputError
        from .asset_h5 import read_asset

        self.summary(name)
        asset = read_asset(self.asset_path(name))
        try:
            if asset.name != name:
                raise InputError(f"its file holds an asset named {asset.name!r}")
            asset.validate()
        except (InputError, ValueError, IndexError, TypeError) as exc:  # arrays of the wrong kind too
            why = exc.message if isinstance(exc, InputError) else f"{type(exc).__name__}: {exc}"
            raise StoreError(
                f"asset {name!r} in the bank is damaged: {why.removeprefix(f'asset {name!r}: ')}",
                hint=f"add it again with `zooctl bank add FILE --name {name} --replace`, "
                f"or remove it with `zooctl bank rm {name}`",
            ) from None
        return asset

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def __len__(self) -> int:
        return len(self._entries())

    # -- writing ---------------------------------------------------------------------------
    def add(self, asset: RiggedAsset, replace: bool = False, views_pending: bool = False) -> dict[str, Any]:
        """Store an asset atomically; returns its summary.

        The HDF5 file is built in memory outside the lock (slow part, concurrent writers proceed
        in parallel); the existence check, the publish and the index update happen under it.
        ``views_pending``: the caller renders its retrieval views next; the index entry says so
        until they are stored (`update_summary` with ``views``), so an add killed in between is
        reported by `cleanup` and finished by `bank repair` (`views_pending`).
        """
        from .asset_h5 import card_of, fill_asset

        asset.validate()
        name = check_name(asset.name, "asset name")
        if not replace and self.exists(name):
            raise self.exists_error(name)
        image = h5_image(lambda f: fill_asset(f, asset), libver="latest")
        summary = asset.summary()
        card = json.dumps(card_of(asset), indent=1).encode()
        entry = {**summary, PENDING: True} if views_pending else summary
        self.publish_item(
            name, entry, [(self.asset_path(name), image), (self.card_path(name), card)], replace
        )
        return summary

    def remove_files(self, name: str) -> None:
        from .views_h5 import views_path

        for p in (self.asset_path(name), self.card_path(name), views_path(self.root, name)):
            p.unlink(missing_ok=True)

    def update_summary(self, name: str, **fields: Any) -> None:
        """Change fields of an asset's index entry (tags, license) under the lock. Its ``views``
        stored, its views are no longer pending."""
        with store_lock(self.root), writing(f"updating asset {name!r}"):
            index = self._read_index()
            if name not in index["assets"]:
                raise self._not_found(name, index["assets"])
            index["assets"][name].update(fields)
            if "views" in fields:
                index["assets"][name].pop(PENDING, None)
            write_json_atomic(self.index_path, index)

    def views_pending(self, summaries: list[dict[str, Any]] | None = None) -> list[str]:
        """Assets whose `bank add` stored them but was stopped (killed) before their retrieval
        views were: `bank search` leaves them out until `bank repair` renders them
        (``summaries``: a `list()` already read)."""
        rows = self.list() if summaries is None else summaries
        return [s["name"] for s in rows if s.get(PENDING) is True and not isinstance(s.get("views"), dict)]

    def cleanup(self) -> dict[str, Any]:
        """`IndexedStore.cleanup`, and the assets whose views a killed `bank add` left unrendered
        (``views_pending``: kept, `bank repair` renders them)."""
        report = super().cleanup()
        report["views_pending"] = self.views_pending()
        return report

    def set_label(self, name: str, label: str, source: str) -> dict[str, Any]:
        """Record what animal an asset is (``label``, and where it came from: ``source``) in its
        file's meta, its card and its index entry, each replaced atomically under the lock.
        Its retrieval views stay valid (`views_h5.summary_digest` leaves the label out)."""
        import shutil

        import h5py

        from .asset_h5 import card_of, read_asset
        from .fs import publish, temp_path

        fields = {"label": label, "label_source": source}
        with store_lock(self.root), writing(f"labelling asset {name!r}"):
            index = self._read_index()
            if name not in index["assets"]:
                raise self._not_found(name, index["assets"])
            path = self.asset_path(name)
            tmp = temp_path(path)
            try:
                shutil.copyfile(path, tmp)
                with h5py.File(tmp, "r+") as f:
                    meta = json.loads(f.attrs.get("meta", "{}"))
                    meta.update(fields)
                    f.attrs["meta"] = json.dumps(meta, default=str)
                publish(tmp, path)
            finally:
                tmp.unlink(missing_ok=True)
            try:
                card = json.loads(self.card_path(name).read_bytes())
                card["meta"].update(fields)
            except (OSError, ValueError, KeyError, AttributeError, TypeError):
                card = card_of(read_asset(path))
            card.update(fields)
            write_bytes_atomic(self.card_path(name), json.dumps(card, indent=1).encode())
            index["assets"][name].update(fields)
            write_json_atomic(self.index_path, index)
            return index["assets"][name]

    def remove_leftovers(self, keep: set[str]) -> tuple[int, int]:
        """Cards and retrieval sidecars of assets that are gone, pack files nothing refers to."""
        from .fs import remove_stale_temps
        from .views_h5 import unreferenced_files, views_dir

        temps, orphans = remove_stale_temps(views_dir(self.root)), 0
        for p in unreferenced_files(self.root, keep):
            p.unlink(missing_ok=True)
            orphans += 1
        if self.assets_dir.is_dir():
            for p in self.assets_dir.glob("*.json"):
                if not p.name.startswith(".") and p.stem not in keep:
                    p.unlink(missing_ok=True)
                    orphans += 1
        return temps, orphans

    # -- repair ----------------------------------------------------------------------------
    def rebuild_entry(
        self, name: str, path: Path, old: dict[str, Any] | None
    ) -> tuple[dict[str, Any], list[str]]:
        from .asset_h5 import card_of, read_asset

        asset = self.checked_item(read_asset(path), name, path)
        entry = asset.summary()
        if old is not None and all(old.get(k) == entry[k] for k in ("vertices", "faces", "joints", "tags")):
            entry = dict(old)  # the same asset: keep what was recorded (its views entry above all)
        notes = []
        views = self._views_entry(name, entry)
        from .views_h5 import views_path

        if views is None and ("views" in entry or views_path(self.root, name).exists()):
            notes.append("its retrieval views are gone or damaged (run `zooctl bank reindex --missing`)")
        entry.pop("views", None)
        if views is not None:
            entry["views"] = views
            entry.pop(PENDING, None)  # a killed add had stored them, all but its index entry
        try:
            card = json.loads(read_regular(self.card_path(name)))
            ok = isinstance(card, dict) and isinstance(card.get("joint_names"), list)
        except (OSError, ValueError, RecursionError):
            ok = False
        if not ok:
            write_bytes_atomic(self.card_path(name), json.dumps(card_of(asset), indent=1).encode())
            notes.append("card rewritten")
        return entry, notes

    def _views_entry(self, name: str, entry: dict[str, Any]) -> dict[str, Any] | None:
        """The ``views`` entry of an asset whose sidecar is intact and belongs to this asset."""
        from .views_h5 import read_views, summary_digest, views_path

        p = views_path(self.root, name)
        if not p.is_file():
            return None
        try:
            sv = read_views(p)
        except Exception:  # a damaged sidecar is no views: `bank reindex` renders them again
            return None
        if sv.asset != name or sv.asset_digest != summary_digest(entry):
            return None
        old = entry.get("views")
        if isinstance(old, dict) and old.get("views_id") == sv.views_id:
            return old
        return {
            "count": sv.count,
            "size": sv.size,
            "embedders": {e: int(a.shape[1]) for e, a in sv.embeddings.items()},
            "views_id": sv.views_id,
        }
