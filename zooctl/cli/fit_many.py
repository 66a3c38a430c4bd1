"""`zooctl fit VIDEO VIDEO...` (or one with --executor): a batch of fits, one task per video."""

from __future__ import annotations

from pathlib import Path

from ..errors import UsageError
from ..fit.config import FitConfig
from ._common import store_root
from .batch_opts import BatchOptions, report_batch, run_cli_batch


def wants_batch(videos: list[str], executor: str | None) -> bool:
    from ..pipelines.batch_fit import expand_inputs

    return executor is not None or len(expand_inputs(videos)) != 1


def fit_many(
    videos: list[str],
    cfg: FitConfig,
    *,
    template: str | None,
    masks: str | None,
    box: str | None,
    out: Path | None,
    name: str | None,
    cameras: str | None,
    resume: bool,
    json_out: bool,
    replace: bool = False,
    batch: BatchOptions,
) -> None:
    from ..pipelines.batch_fit import (
        commit_fit,
        expand_inputs,
        fit_task,
        plan_fits,
        refresh_search_packs,
        skip_finished,
    )

    if name is not None or box is not None:
        raise UsageError("--name and --box are for one video", hint="a batch names each fit after its video")
    if cameras not in (None, "gt"):
        raise UsageError("--cameras FILE is for one video", hint="a batch takes --cameras gt only")
    from ..fit.template import check_bank_ready
    from ..store.bank import Bank

    if not resume:  # before any worker decodes a video
        check_bank_ready(Bank.open(store_root()), template)
    items = plan_fits(
        expand_inputs(videos),
        store_root(),
        cfg.to_dict(),
        template=template,
        masks=masks,
        out_root=out if out is not None else Path("fits"),
        cameras=cameras,
        keep_existing=not (resume or replace),
    )
    if template is None:
        refresh_search_packs(store_root())
    ex = batch.make_executor(cfg.device, fits=len(items))
    report = run_cli_batch(ex, fit_task, items, commit_fit, skip_finished if resume else None, json_out)

    def row(r):
        s = r.summary
        iou = s.get("mask_iou")
        return [
            str(s.get("template") or ""),
            "" if iou is None else f"{iou:.3f}",
            "" if s.get("fit_s") is None else f"{s['fit_s']:.1f}",
            str(s.get("out") or ""),
        ]

    cols = [("template", "left"), ("mask IoU", "right"), ("fit s", "right"), ("outputs", "left")]
    report_batch(report, json_out, "fits", cols, row)
