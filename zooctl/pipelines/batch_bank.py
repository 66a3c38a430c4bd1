"""`bank add FILES... --executor` and `bank reindex --executor`: import, render and embed in
workers; the driver stores each asset and its views.

Workers read the input files (and, for reindex, the stored asset) by path: a shared file system,
or the same files at the same paths. They return the imported `RiggedAsset` and its computed
views (`zooctl.retrieval.index.ComputedViews`); the driver adds them with `Bank.add` and
`store_views`, each an atomic publish under the store's lock. An asset whose views were not
stored yet (the batch stopped between the two) gets them from ``--resume``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import UsageError, ZooctlError
from ..names import check_name, sanitize_name
from ..store.bank import Bank
from .batch import BatchItem


@dataclass
class BankTask:
    store: str
    name: str
    path: str | None  # the file to import; None: re-render the stored asset's views
    views: bool = True
    embedders: list[str] = field(default_factory=list)
    tags: list[str] = field(default_factory=list)
    license: str | None = None
    replace: bool = False
    n_views: int | None = None
    size: int | None = None
    device: str = "cpu"
    limits: dict[str, Any] = field(default_factory=dict)  # `bank add --max-*`, applied in the worker
    label: str | None = None  # `bank add --label`


def _has_views(bank: Bank, name: str, embedders: list[str]) -> bool:
    v = bank.summary(name).get("views")
    return isinstance(v, dict) and set(embedders) <= set(v.get("embedders", {}))


def plan_add(
    bank: Bank,
    paths: list[Path],
    name: str | None = None,
    tags: list[str] | None = None,
    license: str | None = None,
    replace: bool = False,
    views: bool = True,
    resume: bool = False,
    device: str = "cpu",
    limits: dict[str, Any] | None = None,
    label: str | None = None,
) -> list[BatchItem]:
    from ..retrieval.index import enabled_embedders
    from ..retrieval.labels import check_label

    if label is not None:
        check_label(label)

    if name is not None and len(paths) > 1:
        raise UsageError("--name needs exactly one PATH", hint="add the files one at a time, or drop --name")
    embedders = enabled_embedders() if views else []
    items, seen = [], set()
    for p in paths:
        key = check_name(name, "asset name") if name else sanitize_name(Path(p).stem)
        task = BankTask(str(bank.root), key, str(Path(p).resolve()), views, embedders, sorted(tags or []))
        task.license, task.replace, task.device, task.label = license, replace, device, label
        task.limits = {k: v for k, v in (limits or {}).items() if v is not None}
        item = BatchItem(key, task, str(p))
        if key in seen:
            item.error = UsageError(
                f"two files in this batch would be named {key!r}", hint="add it alone with --name"
            )
        elif bank.exists(key) and not replace:
            if not resume:
                item.error = bank.exists_error(key)
            elif views and not _has_views(bank, key, embedders):
                task.path = None  # stored before the batch stopped: only its views are missing
        seen.add(key)
        items.append(item)
    return items


def plan_reindex(
    bank: Bank, names: list[str], embedders: list[str], n_views: int, size: int, device: str
) -> list[BatchItem]:
    items = []
    for n in names:
        task = BankTask(str(bank.root), n, None, True, embedders, n_views=n_views, size=size, device=device)
        item = BatchItem(n, task, n)
        try:
            bank.summary(n)
        except ZooctlError as exc:  # not in the bank: says so with close names
            item.error = exc
        items.append(item)
    return items


def bank_task(task: BankTask, report) -> dict[str, Any]:
    """Worker side: import the file (or read the stored asset) and compute its views."""
    from ..limits import import_limits
    from ..retrieval.index import compute_views
    from ..retrieval.views import DEFAULT_SIZE, DEFAULT_VIEWS
    from ..store import views_h5
    from .bank_import import import_file

    bank, summary, digest = Bank.open(Path(task.store)), None, None
    if task.path is not None:
        report("import")
        with import_limits(**task.limits):
            asset = import_file(Path(task.path), task.name)
        if task.tags:
            asset.meta["tags"] = sorted(set(asset.meta.get("tags", [])) | set(task.tags))
        if task.license is not None:
            asset.meta["license"] = task.license
        from ..retrieval.labels import label_asset

        label_asset(asset, task.label)
    else:
        report("read")
        asset, summary = bank.get(task.name), bank.summary(task.name)
        digest = views_h5.summary_digest(summary)
    cv = None
    if task.views:
        report("views")
        cv = compute_views(
            bank,
            asset,
            summary,
            task.embedders,
            task.n_views or DEFAULT_VIEWS,
            task.size or DEFAULT_SIZE,
            device=task.device,
        )
    return {"asset": asset if task.path is not None else None, "views": cv, "digest": digest}


def commit_bank(item: BatchItem, value: dict[str, Any]) -> dict[str, Any]:
    """Driver side: add the asset, then its views (each atomic, under the store's lock)."""
    from ..retrieval.index import store_views

    task: BankTask = item.payload
    bank = Bank.open(Path(task.store))
    summary = (
        bank.add(value["asset"], replace=task.replace, views_pending=value["views"] is not None)
        if value["asset"] is not None
        else bank.summary(task.name)
    )
    if value["views"] is not None:
        try:
            entry = store_views(bank, task.name, value["views"], value["digest"])
        except ZooctlError as exc:
            if value["asset"] is None:
                raise
            raise type(exc)(
                f"{task.name} was added, but its retrieval views failed: {exc.message}",
                hint=f"run `zooctl bank reindex {task.name}`",
            ) from None
        summary = {**summary, "views": entry}
    return asset_summary(summary)


def asset_summary(s: dict[str, Any]) -> dict[str, Any]:
    v = s.get("views") if isinstance(s.get("views"), dict) else {}
    return {
        "name": s.get("name"),
        "vertices": s.get("vertices"),
        "joints": s.get("joints"),
        "views": v.get("count", 0),
        "embedders": sorted(v.get("embedders", {})),
    }


def skip_stored(item: BatchItem) -> dict[str, Any] | None:
    """``--resume``: an asset the bank holds (with its views, when they are wanted) is done."""
    task: BankTask = item.payload
    bank = Bank.open(Path(task.store))
    if task.path is None or not bank.exists(task.name):
        return None
    if task.views and not _has_views(bank, task.name, task.embedders):
        return None
    return asset_summary(bank.summary(task.name))
