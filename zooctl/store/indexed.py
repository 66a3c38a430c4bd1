"""One base for the name-keyed stores (bank, videos, fits, motion priors) and the index logic that
the two indexed ones (bank, videos) share: reading and checking ``index.json``, publishing and
removing an item with its index entry, rebuilding the index from the stored files (`repair`), and
cleaning up without ever deleting a stored item.

A missing or damaged index is an error naming the repair command, never an empty store: reading it
as empty once made `clean` delete every stored file and `add` write an index of one. Reads never
write, so the same holds on a read-only store. Only a store with no item files has no index.
"""

from __future__ import annotations

import difflib
import json
from collections.abc import Iterable
from pathlib import Path
from typing import Any, TypeVar

from ..errors import AlreadyExistsError, NotFoundError, StoreError
from ..names import check_name
from .fs import (
    json_bytes,
    publish,
    read_regular,
    remove_stale_temps,
    store_lock,
    temp_path,
    write_json_atomic,
    writing,
)

INDEX_VERSION = 1
S = TypeVar("S", bound="NamedStore")


class NamedStore:
    """What every store of named items shares: names, and the errors for unknown or taken ones."""

    noun = "item"  # "asset", "video", "fit", "motion prior"
    article = "an"
    place = "the store"  # where items live, for messages: "the bank", "the store"
    list_cmd = "zooctl"  # the command that lists them, for hints
    exists_hint = "pass --replace to overwrite it, or --name to choose another name"
    folder = "items"  # the store's folder under the root

    def __init__(self, root: str | Path):
        self.root = Path(root)
        self.dir = self.root / self.folder

    @classmethod
    def open(cls: type[S], root: str | Path) -> S:
        return cls(root)

    def names(self) -> list[str]:  # pragma: no cover - every store defines it
        raise NotImplementedError

    def _not_found(self, name: str, known: Iterable[str] | None = None) -> NotFoundError:
        close = difflib.get_close_matches(name, list(self.names() if known is None else known), n=3)
        hint = f"did you mean {', '.join(close)}?" if close else f"see `{self.list_cmd}`"
        return NotFoundError(f"no {self.noun} named {name!r} in {self.place} at {self.root}", hint=hint)

    def exists_error(self, name: str) -> AlreadyExistsError:
        return AlreadyExistsError(
            f"{self.article} {self.noun} named {name!r} is already in {self.place}", hint=self.exists_hint
        )


class IndexedStore(NamedStore):
    """A folder of ``<name>.h5`` item files plus ``index.json`` {"schema_version", KEY: {name: entry}}.

    Subclasses set `key`, `label`, `repair_cmd`, `required` (entry field -> type) and implement
    `rebuild_entry` (read and check one item file, return its index entry).
    """

    key = "items"
    label = "index"  # "bank index"
    repair_cmd = "zooctl repair"
    required: dict[str, type | tuple[type, ...]] = {}

    @property
    def files_dir(self) -> Path:
        """The folder of the ``<name>.h5`` item files (`dir` holds index.json)."""
        return self.dir

    @property
    def index_path(self) -> Path:
        return self.dir / "index.json"

    # -- reading -------------------------------------------------------------------------------
    def item_files(self) -> dict[str, Path]:
        """{name: path} of every stored item file, indexed or not (temporaries are hidden files)."""
        try:
            return {
                p.stem: p
                for p in sorted(self.files_dir.glob("*.h5"))
                if not p.name.startswith(".") and p.is_file()
            }
        except OSError:
            return {}

    def _damaged(self, why: str) -> StoreError:
        return StoreError(
            f"the {self.label} {self.index_path} is damaged: {why}",
            hint=f"run `{self.repair_cmd}` to rebuild it from the stored files",
        )

    def _read_index(self) -> dict[str, Any]:
        try:
            text = read_regular(self.index_path)
        except FileNotFoundError:
            n = len(self.item_files())
            if n:
                raise StoreError(
                    f"the {self.label} {self.index_path} is missing, but {n} {self.noun} files are stored",
                    hint=f"run `{self.repair_cmd}` to rebuild it from them",
                ) from None
            return {"schema_version": INDEX_VERSION, self.key: {}}
        except OSError as exc:
            raise StoreError(
                f"the {self.label} {self.index_path} is unreadable: {exc.strerror}",
                hint=f"check its permissions; if it is damaged, run `{self.repair_cmd}`",
            ) from None
        try:
            data = json.loads(text)
        except (ValueError, RecursionError) as exc:  # UnicodeDecodeError is a ValueError
            raise self._damaged(f"not JSON ({str(exc)[:80]})") from None
        return self._check_index(data)

    def _check_index(self, data: Any) -> dict[str, Any]:
        if not isinstance(data, dict) or "schema_version" not in data:
            raise self._damaged("it is not a zooctl index (no schema_version)")
        v = data["schema_version"]
        if isinstance(v, int) and not isinstance(v, bool) and v > INDEX_VERSION:
            raise StoreError(
                f"the {self.label} has schema version {v}, this zooctl reads {INDEX_VERSION}",
                hint="upgrade zooctl",
            )
        if v != INDEX_VERSION:
            raise self._damaged(f"unknown schema version {v!r}")
        items = data.get(self.key)
        if not isinstance(items, dict):
            raise self._damaged(f"no {self.key!r} table")
        for name, entry in items.items():
            problem = self.check_entry(name, entry)
            if problem:
                raise self._damaged(f"entry {name!r} {problem}")
        return data

    def check_entry(self, name: str, entry: Any) -> str | None:
        """What is wrong with one index entry (None: nothing). Cheap: runs on every read."""
        if not isinstance(entry, dict):
            return "is not a table"
        for f, t in self.required.items():
            if f not in entry:
                return f"lacks {f!r}"
            if not isinstance(entry[f], t):
                return f"has a bad {f!r}"
        if entry.get("name") != name:
            return "names another item"
        return None

    def _entries(self) -> dict[str, Any]:
        return self._read_index()[self.key]

    def names(self) -> list[str]:
        return sorted(self._entries())

    def exists(self, name: str) -> bool:
        return name in self._entries()

    def list(self) -> list[dict[str, Any]]:
        items = self._entries()
        return [items[n] for n in sorted(items)]

    def summary(self, name: str) -> dict[str, Any]:
        items = self._entries()
        if name not in items:
            raise self._not_found(name, items)
        return items[name]

    # -- writing -------------------------------------------------------------------------------
    def publish_item(
        self, name: str, summary: dict[str, Any], files: list[tuple[Path, bytes]], replace: bool
    ) -> None:
        """Store an item's ``files`` ((final path, content), the item file first) and its index
        entry ``summary``, atomically.

        The files are written to temporaries outside the lock (the slow part: concurrent writers
        proceed in parallel); under it the name is checked again and the index is checked for room
        before any file is replaced, so a full disk fails with the store as it was. The index is
        replaced last: the item exists once the index names it."""
        temps = [temp_path(final) for final, _ in files]
        try:
            with writing(f"adding {self.noun} {name!r}"):
                for tmp, (_, content) in zip(temps, files):
                    tmp.write_bytes(content)
            self.publish_written(
                name, summary, [(tmp, final) for tmp, (final, _) in zip(temps, files)], replace
            )
        finally:
            for tmp in temps:
                tmp.unlink(missing_ok=True)

    def publish_written(
        self, name: str, summary: dict[str, Any], written: list[tuple[Path, Path]], replace: bool
    ) -> None:
        """`publish_item` for files already written to temporaries ((temporary from `temp_path`,
        final path), the item file first): under the lock the name is checked again, then the
        files and the index entry are published. The temporaries are gone afterwards either way."""
        try:
            with writing(f"adding {self.noun} {name!r}"), store_lock(self.root):
                index = self._read_index()
                if not replace and name in index[self.key]:
                    raise self.exists_error(name)
                index[self.key][name] = summary
                idx_tmp = temp_path(self.index_path)
                try:
                    idx_tmp.write_bytes(json_bytes(index))
                    for tmp, final in written:
                        publish(tmp, final)
                    self.remove_side_data(name)
                    publish(idx_tmp, self.index_path)
                finally:
                    idx_tmp.unlink(missing_ok=True)
        finally:
            for tmp, _ in written:
                tmp.unlink(missing_ok=True)

    def remove(self, name: str) -> None:
        """Remove an item: its index entry first (it is gone once the index says so), then its files."""
        with store_lock(self.root), writing(f"removing {self.noun} {name!r}"):
            index = self._read_index()
            if name not in index[self.key]:
                raise self._not_found(name, index[self.key])
            del index[self.key][name]
            write_json_atomic(self.index_path, index)
            self.remove_files(name)

    def remove_files(self, name: str) -> None:
        """Delete what a removed item leaves: its file and side data."""
        raise NotImplementedError  # pragma: no cover

    def remove_side_data(self, name: str) -> None:
        """Drop data derived from the item ``name`` when a new one is published under it (caches)."""

    # -- repair --------------------------------------------------------------------------------
    def rebuild_entry(
        self, name: str, path: Path, old: dict[str, Any] | None
    ) -> tuple[dict[str, Any], list[str]]:
        """Read and check the item file ``path``; return its index entry and notes on what was
        fixed beside it. ``old`` is its entry in the previous index when that one was usable.
        Raises for a file that is not a valid item."""
        raise NotImplementedError  # pragma: no cover

    def checked_item(self, item: Any, name: str, path: Path) -> Any:
        """``item`` read from ``path``, if it is valid (``item.validate()``) and named ``name``."""
        try:
            item.validate()
        except ValueError as exc:
            raise StoreError(f"the {self.noun} in {path.name} is invalid: {exc}") from None
        if item.name != name:
            raise StoreError(f"{path.name} holds {self.article} {self.noun} named {item.name!r}")
        return item

    def _salvage(self) -> tuple[dict[str, Any], str]:
        """The usable entries of the current index (if any) and what state it was in."""
        try:
            data = json.loads(read_regular(self.index_path))
        except FileNotFoundError:
            return {}, "missing"
        except OSError as exc:
            return {}, f"unreadable ({exc.strerror})"
        except (ValueError, RecursionError):
            return {}, "damaged (not JSON)"
        v = data.get("schema_version") if isinstance(data, dict) else None
        if isinstance(v, int) and not isinstance(v, bool) and v > INDEX_VERSION:
            self._check_index(data)  # written by a newer zooctl: raises, never rewritten here
        try:
            self._check_index(data)
            return dict(data[self.key]), "ok"
        except StoreError as exc:
            items = data.get(self.key) if isinstance(data, dict) else None
            items = items if isinstance(items, dict) else {}
            good = {n: e for n, e in items.items() if not self.check_entry(n, e)}
            return good, "damaged (" + exc.message.split(": ", 1)[-1] + ")"

    def repair(self) -> dict[str, Any]:
        """Rebuild the index from the item files: valid ones are indexed, the others are reported
        (and left where they are). Never deletes a file."""
        with store_lock(self.root), writing(f"repairing the {self.label}"):
            old, previous = self._salvage()
            items: dict[str, Any] = {}
            skipped: dict[str, str] = {}
            fixed: list[str] = []
            for name, path in self.item_files().items():
                try:
                    check_name(name, f"{self.noun} name")
                    entry, notes = self.rebuild_entry(name, path, old.get(name))
                except StoreError as exc:
                    skipped[name] = exc.message
                    continue
                except Exception as exc:  # any failure to read a file makes it invalid, nothing more
                    skipped[name] = f"{type(exc).__name__}: {exc}"
                    continue
                items[name] = entry
                fixed += [f"{name}: {n}" for n in notes]
            new = {"schema_version": INDEX_VERSION, self.key: items}
            written = previous != "ok" or items != old
            if written:
                write_json_atomic(self.index_path, new)
        return {
            "previous": previous,
            "indexed": sorted(items),
            "skipped": skipped,
            "dropped": sorted(set(old) - set(items)),
            "fixed": fixed,
            "written": written,
        }

    # -- cleaning ------------------------------------------------------------------------------
    def cleanup(self) -> dict[str, Any]:
        """Remove what killed writers left: temporaries of dead processes and the leftovers of
        items that are gone (`remove_leftovers`). Item files the index does not name are kept and
        reported (`repair` indexes the valid ones)."""
        with store_lock(self.root), writing(f"cleaning the {self.key}"):
            items = self._entries()  # a missing or damaged index stops here: nothing is deleted
            temps = remove_stale_temps(self.files_dir)
            if self.dir != self.files_dir:
                temps += remove_stale_temps(self.dir)
            more_temps, orphans = self.remove_leftovers(set(items) | set(self.item_files()))
        return {"temporaries": temps + more_temps, "orphans": orphans, "unindexed": self.unindexed(items)}

    def remove_leftovers(self, keep: set[str]) -> tuple[int, int]:
        """Delete side files (cards, caches...) of items not in ``keep``; (temporaries, orphans)."""
        return 0, 0

    def unindexed(self, items: dict[str, Any]) -> list[str]:
        """Item files the index does not name: kept by `cleanup`, indexed by `repair` if valid."""
        return sorted(set(self.item_files()) - set(items))
