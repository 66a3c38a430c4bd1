"""`bank add FILES... --executor` and `bank reindex --executor`: the batch forms."""

from __future__ import annotations

from pathlib import Path

from ._common import open_bank
from .batch_opts import BatchOptions, report_batch, run_cli_batch


def _row(r) -> list[str]:
    s = r.summary
    return [str(s.get("vertices") or ""), str(s.get("joints") or ""), str(s.get("views") or "")]


_COLS = [("vertices", "right"), ("joints", "right"), ("views", "right")]


def add_many(
    paths: list[Path],
    *,
    name: str | None,
    tags: list[str] | None,
    license: str | None,
    replace: bool,
    views: bool | None,
    resume: bool,
    json_out: bool,
    batch: BatchOptions,
    device: str = "cpu",
    limits: dict | None = None,
    label: str | None = None,
) -> None:
    from ..pipelines.bank_import import views_by_default
    from ..pipelines.batch_bank import bank_task, commit_bank, plan_add, skip_stored

    bank = open_bank()
    views = views_by_default() if views is None else views
    items = plan_add(bank, paths, name, tags, license, replace, views, resume, device, limits, label)
    ex = batch.make_executor(device)
    report = run_cli_batch(ex, bank_task, items, commit_bank, skip_stored if resume else None, json_out)
    report_batch(report, json_out, "assets", _COLS, _row)


def reindex_many(
    names: list[str],
    embedders: list[str],
    n_views: int,
    size: int,
    device: str,
    *,
    json_out: bool,
    batch: BatchOptions,
) -> None:
    from ..pipelines.batch_bank import bank_task, commit_bank, plan_reindex

    items = plan_reindex(open_bank(), names, embedders, n_views, size, device)
    ex = batch.make_executor(device)
    report = run_cli_batch(ex, bank_task, items, commit_bank, None, json_out)
    report_batch(report, json_out, "assets", _COLS, _row)
