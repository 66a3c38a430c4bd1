"""`bank add`: import files through the registered importers and store them in the bank."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..asset import RiggedAsset
from ..errors import InputError, UsageError, ZooctlError
from ..files import regular_size
from ..names import check_name, sanitize_name
from ..plugins import get_registry
from ..store.bank import Bank


@dataclass
class AddResult:
    path: Path
    name: str
    summary: dict[str, Any] | None = None
    error: ZooctlError | None = None


def import_file(path: Path, name: str) -> RiggedAsset:
    """Read one file into a validated `RiggedAsset` with the importer its suffix selects."""
    path = Path(path)
    if not path.exists():
        raise InputError(f"{path} does not exist")
    registry = get_registry()
    spec = registry.importer_for(path.suffix)
    if spec is None:
        if path.is_dir():
            raise InputError(f"{path} is a directory", hint="give the model file(s) inside it")
        known = sorted({s for sp in registry.components["importer"].values() for s in sp.suffixes})
        raise InputError(
            f"cannot import {path.name}: unknown file type {path.suffix or '(none)'!r}",
            hint=f"supported: {' '.join(known)}",
        )
    if path.is_dir():
        raise InputError(f"{path} is a directory", hint="give the model file(s) inside it")
    regular_size(path, "the model file", "max_file_mb")  # a FIFO or /dev/zero would never end
    return spec.load(path, name)


def add_files(
    bank: Bank,
    paths: list[Path],
    name: str | None = None,
    tags: list[str] | None = None,
    license: str | None = None,
    replace: bool = False,
    views: bool | None = None,
    progress: Callable[[str, int, int], None] | None = None,
    label: str | None = None,
) -> list[AddResult]:
    """Import and store each path; one bad file does not stop the others (its result holds the error).

    ``views`` renders and embeds each added asset's retrieval views (`zooctl.retrieval.index`);
    default: on, unless the environment sets ZOOCTL_VIEWS=0. ``progress(stage, done, total)`` is
    called after each file. ``label``: what animal the assets are (`zooctl.retrieval.labels`;
    default: what their names, tags or views show).
    """
    from ..retrieval.labels import check_label, label_asset

    views = views_by_default() if views is None else views
    if label is not None:
        check_label(label)
    if name is not None and len(paths) > 1:
        raise UsageError("--name needs exactly one PATH", hint="add the files one at a time, or drop --name")
    if name is not None:
        check_name(name, "asset name")
    results = []
    for p in paths:
        asset_name = name or sanitize_name(Path(p).stem)
        r = AddResult(Path(p), asset_name)
        try:
            if not replace and bank.exists(asset_name):
                raise bank.exists_error(asset_name)
            asset = import_file(Path(p), asset_name)
            if tags:
                asset.meta["tags"] = sorted(set(asset.meta.get("tags", [])) | set(tags))
            if license is not None:
                asset.meta["license"] = license
            label_asset(asset, label)
            new = not bank.exists(asset_name)
            summary = bank.add(asset, replace=replace, views_pending=views)
            if views:
                summary = {**summary, "views": _index_views(bank, asset, undo=new)}
            r.summary = summary
        except ZooctlError as exc:
            r.error = exc
        results.append(r)
        if progress is not None:
            progress("adding", len(results), len(paths))
    return results


def seed_starter(
    bank: Bank,
    seed: int = 0,
    plans: list[str] | None = None,
    variants: bool = True,
    replace: bool = False,
    views: bool | None = None,
    progress: Callable[[str, int, int], None] | None = None,
    random: int = 0,
) -> list[str]:
    """Add the procedural starter animals, or ``random`` random ones (`zooctl.procedural.seed_bank`) and, like `add_files`,
    render their retrieval views, so `bank search` and `fit` retrieval work on a seeded bank.
    Returns the names added."""
    from ..procedural import seed_bank
    from ..procedural.random import random_assets

    views = views_by_default() if views is None else views
    assets = random_assets(random, seed=seed, labels=plans) if random > 0 else None
    added = seed_bank(bank, seed=seed, plans=plans, variants=variants, replace=replace, assets=assets)
    from ..retrieval.labels import relabel

    for n in added:  # the starter animals are named by their body plans
        if not isinstance(bank.summary(n).get("label"), str):
            relabel(bank, n)
    for i, n in enumerate(added if views else []):
        _index_views(bank, bank.get(n))
        if progress is not None:
            progress("views", i + 1, len(added))
    return added


def repair_bank(bank: Bank, progress: Callable[[str, int, int], None] | None = None) -> dict[str, Any]:
    """`bank repair`: the index rebuilt from the asset files (`Bank.repair`), then the retrieval
    views of the assets a killed `bank add` left without them (`Bank.views_pending`) rendered, as
    that add would have. The report adds ``views_rendered`` (names) and ``views_failed`` ({name:
    why}) to `Bank.repair`'s."""
    from ..retrieval.index import index_asset

    report = bank.repair()
    pending = bank.views_pending()
    rendered, failed = [], {}
    for i, n in enumerate(pending):
        try:
            index_asset(bank, bank.get(n))
            rendered.append(n)
        except ZooctlError as exc:
            failed[n] = exc.message
        if progress is not None:
            progress("views", i + 1, len(pending))
    return {**report, "views_rendered": rendered, "views_failed": failed}


def views_by_default() -> bool:
    import os

    return os.environ.get("ZOOCTL_VIEWS", "1") != "0"


def _index_views(bank: Bank, asset, undo: bool = False) -> dict:
    """Render and store the asset's views. ``undo``: the asset is new, so a failure removes it
    again (an asset in the index without its views is a half-done add)."""
    from ..retrieval.index import index_asset

    try:
        return index_asset(bank, asset)
    except ZooctlError as exc:
        if undo:
            try:
                bank.remove(asset.name)
            except ZooctlError:
                pass  # the error below still says what happened
            else:
                raise type(exc)(
                    f"{asset.name} was not added: its retrieval views failed: {exc.message}",
                    hint=exc.hint or "fix that and add it again (or add it with --no-views)",
                ) from None
        raise type(exc)(
            f"{asset.name} was added, but its retrieval views failed: {exc.message}",
            hint=f"fix that, then run `zooctl bank reindex {asset.name}`",
        ) from None
