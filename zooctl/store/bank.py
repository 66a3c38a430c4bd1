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
index does not name (a writer killed between the two replaces) is invisible and overwritten by the
next add of that name.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import AlreadyExistsError, NotFoundError, StoreError
from ..names import check_name
from .fs import publish, remove_stale_temps, store_lock, temp_path, write_json_atomic

if TYPE_CHECKING:  # numpy/h5py stay unimported for `bank list` and `bank show`
    from ..asset import RiggedAsset

INDEX_VERSION = 1


class Bank:
    """The asset bank of one store root."""

    def __init__(self, root: str | Path):
        self.root = Path(root)
        self.dir = self.root / "bank"
        self.assets_dir = self.dir / "assets"
        self.index_path = self.dir / "index.json"

    @classmethod
    def open(cls, root: str | Path) -> Bank:
        return cls(root)

    # -- reading (no lock: every visible file is complete) --------------------------------
    def _read_index(self) -> dict[str, Any]:
        try:
            data = json.loads(self.index_path.read_text())
        except FileNotFoundError:
            return {"schema_version": INDEX_VERSION, "assets": {}}
        except (OSError, json.JSONDecodeError) as exc:
            raise StoreError(f"the bank index {self.index_path} is unreadable: {exc}") from None
        v = data.get("schema_version")
        if v != INDEX_VERSION:
            raise StoreError(
                f"the bank index has schema version {v}, this zooctl reads {INDEX_VERSION}",
                hint="upgrade zooctl"
                if isinstance(v, int) and v > INDEX_VERSION
                else "run `zooctl bank migrate`",
            )
        return data

    def names(self) -> list[str]:
        return sorted(self._read_index()["assets"])

    def exists(self, name: str) -> bool:
        return name in self._read_index()["assets"]

    def list(self) -> list[dict[str, Any]]:
        """Summaries of every asset, sorted by name (from the index alone)."""
        assets = self._read_index()["assets"]
        return [assets[n] for n in sorted(assets)]

    def summary(self, name: str) -> dict[str, Any]:
        assets = self._read_index()["assets"]
        if name not in assets:
            raise self._not_found(name, assets)
        return assets[name]

    def card(self, name: str) -> dict[str, Any]:
        """Summary plus joint tree (what `bank show` prints), without opening the HDF5 file."""
        summary = self.summary(name)
        try:
            card = json.loads(self.card_path(name).read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise StoreError(
                f"the card of asset {name!r} is unreadable: {exc}", hint="re-add the asset with --replace"
            ) from None
        card.update(summary)
        return card

    def asset_path(self, name: str) -> Path:
        return self.assets_dir / f"{name}.h5"

    def card_path(self, name: str) -> Path:
        return self.assets_dir / f"{name}.json"

    def get(self, name: str) -> RiggedAsset:
        """Load an asset. Raises `NotFoundError` when the bank has no such asset."""
        from .asset_h5 import read_asset

        self.summary(name)
        return read_asset(self.asset_path(name))

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())

    def __len__(self) -> int:
        return len(self._read_index()["assets"])

    def _not_found(self, name: str, assets: dict[str, Any]) -> NotFoundError:
        import difflib

        close = difflib.get_close_matches(name, list(assets), n=3)
        hint = f"did you mean {', '.join(close)}?" if close else "see `zooctl bank list`"
        return NotFoundError(f"no asset named {name!r} in the bank at {self.root}", hint=hint)

    # -- writing ---------------------------------------------------------------------------
    def add(self, asset: RiggedAsset, replace: bool = False) -> dict[str, Any]:
        """Store an asset atomically; returns its summary.

        The HDF5 file is written outside the lock (slow part, concurrent writers proceed in
        parallel); the existence check, the publish and the index update happen under it.
        """
        from .asset_h5 import card_of, write_asset

        asset.validate()
        name = check_name(asset.name, "asset name")
        if not replace and self.exists(name):
            raise self.exists_error(name)
        self.assets_dir.mkdir(parents=True, exist_ok=True)
        final = self.asset_path(name)
        tmp = temp_path(final)
        card_tmp = temp_path(self.card_path(name))
        try:
            write_asset(tmp, asset)
            summary = asset.summary()
            card_tmp.write_text(json.dumps(card_of(asset), indent=1))
            with store_lock(self.root):
                index = self._read_index()
                if not replace and name in index["assets"]:
                    raise self.exists_error(name)
                publish(tmp, final)
                publish(card_tmp, self.card_path(name))
                index["assets"][name] = summary
                write_json_atomic(self.index_path, index)
        finally:
            tmp.unlink(missing_ok=True)
            card_tmp.unlink(missing_ok=True)
        return summary

    def remove(self, name: str) -> None:
        with store_lock(self.root):
            index = self._read_index()
            if name not in index["assets"]:
                raise self._not_found(name, index["assets"])
            del index["assets"][name]
            write_json_atomic(self.index_path, index)  # the asset is gone once the index says so
            from .views_h5 import views_path

            for p in (self.asset_path(name), self.card_path(name), views_path(self.root, name)):
                p.unlink(missing_ok=True)

    def update_summary(self, name: str, **fields: Any) -> None:
        """Change fields of an asset's index entry (tags, license) under the lock."""
        with store_lock(self.root):
            index = self._read_index()
            if name not in index["assets"]:
                raise self._not_found(name, index["assets"])
            index["assets"][name].update(fields)
            write_json_atomic(self.index_path, index)

    def cleanup(self) -> dict[str, int]:
        """Remove what killed writers left: temporaries of dead processes and unindexed files
        (asset files, and retrieval-view sidecars and pack files that nothing refers to)."""
        from .views_h5 import unreferenced_files, views_dir

        views = views_dir(self.root)
        with store_lock(self.root):
            temps = (
                remove_stale_temps(self.assets_dir) + remove_stale_temps(self.dir) + remove_stale_temps(views)
            )
            index = self._read_index()
            orphans = 0
            for p in unreferenced_files(self.root, set(index["assets"])):
                p.unlink(missing_ok=True)
                orphans += 1
            if self.assets_dir.is_dir():
                for p in self.assets_dir.iterdir():
                    if (
                        p.suffix in (".h5", ".json")
                        and not p.name.startswith(".")
                        and p.stem not in index["assets"]
                    ):
                        p.unlink(missing_ok=True)
                        orphans += 1
        return {"temporaries": temps, "orphans": orphans}

    def exists_error(self, name: str) -> AlreadyExistsError:
        return AlreadyExistsError(
            f"an asset named {name!r} is already in the bank",
            hint="pass --replace to overwrite it, or --name to choose another name",
        )
