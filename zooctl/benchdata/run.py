"""`bench run`: fit every benchmark video and tabulate CASA's metrics, with ablations.

Each video is fitted with its own asset removed from the template candidates (retrieval sees
the bank minus that asset); ``template`` fixes the template instead, and ``own_template`` fits
each video with its own asset (what a bank that holds the animal allows: the bound the
leave-one-out bank is measured against). Ablations (CASA tables 2-5)
are config switches applied on top of the preset: ``no-flow``, ``no-symmetry``, ``no-smoothness``,
``no-stretch``, ``no-displacement``, ``fixed-skinning``, ``retrieval-only`` and ``shape-kept``
(``no-stretch``, ``no-displacement`` and ``fixed-skinning`` together: `zooctl fit --keep-shape`).

With retrieval, each row also says whether the fit's template has the video's body plan
(`zooctl.retrieval.evaluate.body_plan`), and the summary counts the videos whose plan is right at
retrieval's top-1, among the candidates the template trials tried, and after the trials.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError, UsageError
from ..fit.config import KEEP_SHAPE, FitConfig, preset
from ..fit.inputs import bench_meta

ABLATIONS: dict[str, dict[str, Any]] = {
    "full": {},
    "no-flow": {"ablation": {"flow": False}},
    "no-symmetry": {"ablation": {"symmetry": False}},
    "no-smoothness": {"ablation": {"smoothness": False}},
    "no-stretch": {"ablation": {"stretch": False}},
    "no-displacement": {"ablation": {"displacement": False}},
    "fixed-skinning": {"ablation": {"learn_skinning": False}},
    "retrieval-only": {"ablation": {"optimise": False}},
    "shape-kept": KEEP_SHAPE,
}
COLUMNS = (
    "mask_iou",
    "novel_view_iou",
    "view_psnr",
    "miou",
    "mcham",
    "joint",
    "skinning",
    "reanimation",
    "surface_tear",
    "wall_s",
)
JSON_ONLY = ("tilt_error",)  # in the JSON rows and summary, not the markdown table
# from the fit's record
_FIT_METRICS = tuple(k for k in COLUMNS if k not in ("view_psnr", "wall_s")) + JSON_ONLY


def bench_videos(folder: Path) -> list[Path]:
    vids = (
        sorted(p for p in Path(folder).iterdir() if (p / "video.npz").is_file())
        if Path(folder).is_dir()
        else []
    )
    if not vids:
        raise InputError(
            f"{folder} holds no benchmark videos", hint="make them with `zooctl bench make --out DIR`"
        )
    return vids


def run_benchmark(
    folder: Path,
    store_root: Path,
    preset_name: str = "fast",
    ablations: list[str] | None = None,
    template: str | None = None,
    limit: int | None = None,
    overrides: dict[str, Any] | None = None,
    progress=None,
    known_camera: bool = False,
    own_template: bool = False,
    executor: Any = None,
    resume: bool = False,
    batch_progress: Any = None,
) -> dict[str, Any]:
    """Fit every video under every ablation; returns {"rows": [...], "summary": {ablation: means}}.

    ``known_camera``: each fit is given the video's own camera rotations (CASA's protocol on
    synthetic data) instead of estimating the camera's motion from the masks. ``executor``
    (`zooctl.executors`): each fit is a task of a batch (`zooctl.pipelines.batch_fit`);
    ``resume`` then keeps the fits that finished before (``batch_progress``: its progress)."""
    from ..store.bank import Bank

    abl = ablations or ["full"]
    if own_template and template is not None:
        raise UsageError("--own-template and --template exclude each other")
    for a in abl:
        if a not in ABLATIONS:
            raise UsageError(f"unknown ablation {a!r}", hint=f"use {', '.join(ABLATIONS)}")
    if overrides:  # a bad component name is one error up front, not one per video
        FitConfig.from_dict(json.loads(json.dumps(overrides)), preset(preset_name))
    vids = bench_videos(folder)[: limit or None]
    bank = Bank.open(store_root)
    args = (vids, abl, store_root, preset_name, overrides, template, own_template, known_camera)
    if executor is not None:
        rows = _run_batch(*args, executor, resume, batch_progress)
    else:
        rows = _run_inline(*args, bank, progress)
    plans = _bank_plans(bank)
    video_plans = {v.name: _video_plan(v, plans) for v in vids}
    if template is None and not own_template:
        _add_body_plans(rows, {v.name: _own_asset(v) for v in vids}, plans, video_plans)
    for r in rows:
        r.pop("candidates", None)
        if "error" not in r and video_plans.get(r["video"]):
            r["video_plan"] = video_plans[r["video"]]
    summary = {}
    for a in abl:
        rs = [r for r in rows if r["ablation"] == a and "error" not in r]
        summary[a] = {k: _mean([r.get(k) for r in rs]) for k in COLUMNS + JSON_ONLY}
        summary[a]["videos"] = len(rs)
        if any("plan" in r for r in rs):
            summary[a]["plan"] = plan_counts(rs)
        if any("video_plan" in r for r in rs):
            summary[a]["by_plan"] = plan_means(rs)
    return {
        "rows": rows,
        "summary": summary,
        "preset": preset_name,
        "known_camera": known_camera,
        "own_template": own_template,
        "overrides": overrides or {},
    }


def _config(a: str, preset_name: str, overrides: dict[str, Any] | None) -> FitConfig:
    cfg = FitConfig.from_dict(json.loads(json.dumps(ABLATIONS[a])), preset(preset_name))
    return FitConfig.from_dict(overrides, cfg) if overrides else cfg


def _own_asset(v: Path) -> str:
    return bench_meta(v).get("asset", v.name)


def _video_plan(v: Path, plans: dict[str, str | None]) -> str | None:
    """The body plan of the animal in benchmark video ``v``: its asset's in the bank (``plans``:
    `_bank_plans`), else the one `make_video` recorded (held-out animals made from another bank)."""
    meta = bench_meta(v)
    plan = plans.get(meta.get("asset", v.name)) or meta.get("body_plan")
    return plan if isinstance(plan, str) and plan else None


def _run_inline(
    vids, abl, store_root, preset_name, overrides, template, own_template, known_camera, bank, progress
):
    from ..fit.job import fit_job

    rows = []
    for a in abl:
        for v in vids:
            cfg = _config(a, preset_name, overrides)
            asset = _own_asset(v)
            t = time.perf_counter()
            name = f"bench-{v.name}-{a}".lower()
            try:
                rec = fit_job(
                    str(v),
                    store_root,
                    cfg,
                    name=name,
                    template=asset if own_template else template,
                    exclude=set() if own_template else {asset},
                    bank=bank,
                    outputs=("loss",),
                    cameras="gt" if known_camera else None,
                    replace=True,
                )
                m = rec["metrics"]
                row = {
                    "video": v.name,
                    "ablation": a,
                    "template": rec["template"],
                    "candidates": rec.get("retrieval") or [],
                    "wall_s": time.perf_counter() - t,
                }
                row.update({k: m.get(k) for k in _FIT_METRICS})
                row.update(_colour_error(store_root, name, v))
            except UsageError as exc:
                row = {"video": v.name, "ablation": a, "error": exc.message}
            rows.append(row)
            if progress:
                progress(row)
    return rows


def _run_batch(
    vids,
    abl,
    store_root,
    preset_name,
    overrides,
    template,
    own_template,
    known_camera,
    executor,
    resume,
    progress,
):
    """Every (ablation, video) fit one task; rows in the inline order, failures as error rows."""
    from ..pipelines.batch import BatchItem, run_batch
    from ..pipelines.batch_fit import FitTask, commit_fit, fit_task, refresh_search_packs, skip_finished

    items = []
    for a in abl:
        cfg = _config(a, preset_name, overrides).to_dict()
        for v in vids:
            asset, name = _own_asset(v), f"bench-{v.name}-{a}".lower()
            task = FitTask(
                str(store_root),
                str(v.resolve()),
                name,
                cfg,
                template=asset if own_template else template,
                exclude=() if own_template else (asset,),
                outputs=("loss",),
                cameras="gt" if known_camera else None,
            )
            items.append(BatchItem(name, task, f"{v.name} [{a}]"))
    if template is None and not own_template:
        refresh_search_packs(store_root)
    report = run_batch(executor, fit_task, items, commit_fit, skip_finished if resume else None, progress)
    by_key = {r.key: r for r in report.results}
    rows = []
    for it in items:
        r = by_key[it.key]
        v, a = Path(it.payload.source).name, it.label.rsplit(" [", 1)[1][:-1]
        if r.status == "failed":
            rows.append({"video": v, "ablation": a, "error": r.error})
            continue
        m = r.summary.get("metrics", {})
        row = {
            "video": v,
            "ablation": a,
            "template": r.summary["template"],
            "candidates": r.summary.get("retrieval") or [],
            "wall_s": r.summary.get("fit_s"),
        }
        rows.append(
            row | {k: m.get(k) for k in _FIT_METRICS} | _colour_error(store_root, it.key, it.payload.source)
        )
    return rows


def _colour_error(store_root: Path, name: str, video: str | Path) -> dict[str, Any]:
    """``view_psnr`` and ``input_psnr`` of a finished fit of a textured video (`appearance`)."""
    from .appearance import fit_psnr

    res = fit_psnr(Path(store_root), name, Path(video))
    if res is None:
        return {}
    return {"view_psnr": res["view_psnr"], "input_psnr": res["input_psnr"]}


def _bank_plans(bank) -> dict[str, str | None]:
    """Each bank asset's body plan (None where it has no label), from the cards: no asset file is
    opened."""
    from ..errors import ZooctlError
    from ..retrieval.evaluate import plan_label

    plans: dict[str, str | None] = {}
    for n in (s["name"] for s in bank.list()):
        try:
            plans[n] = plan_label(n, bank.card(n).get("meta"))
        except ZooctlError:
            plans[n] = None
    return plans


def _add_body_plans(
    rows: list[dict[str, Any]],
    own: dict[str, str],
    plans: dict[str, str | None],
    video_plans: dict[str, str | None],
) -> None:
    """Each fitted row gets ``plan``: the body plans of its video (``video_plans``: `_video_plan`)
    and template (``plans``: `_bank_plans`), and whether the template, retrieval's top-1 and any
    candidate the trials tried have the video's plan (None where the video has no label);
    ``answerable``: another bank asset has it."""
    for r in rows:
        if "error" in r:
            continue
        asset = own.get(r["video"], r["video"])
        want = video_plans.get(r["video"])
        cands = r.pop("candidates", None) or []
        tried = [c["name"] for c in cands if c.get("trial_iou") is not None] or [r["template"]]

        def right(name: str | None, want: str | None = want) -> bool | None:
            return None if want is None or name is None else plans.get(name) == want

        r["plan"] = {
            "video": want,
            "template": plans.get(r["template"]),
            "right": right(r["template"]),
            "top1_right": right(cands[0]["name"] if cands else r["template"]),
            "tried_right": None if want is None else any(right(n) for n in tried),
            "answerable": want is not None and any(p == want for n, p in plans.items() if n != asset),
        }


def plan_counts(rows: list[dict[str, Any]]) -> dict[str, int]:
    """How many of ``rows`` (with ``plan``) are labelled, answerable, and right at retrieval's
    top-1, among the tried candidates and after the trials."""
    ps = [r["plan"] for r in rows if r.get("plan", {}).get("video") is not None]
    return {
        "labelled": len(ps),
        "answerable": sum(p["answerable"] for p in ps),
        "top1": sum(bool(p["top1_right"]) for p in ps),
        "tried": sum(bool(p["tried_right"]) for p in ps),
        "template": sum(bool(p["right"]) for p in ps),
    }


PLAN_COLUMNS = ("mask_iou", "novel_view_iou", "miou")


def plan_means(rows: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per body plan of the videos (``video_plan``): how many, the means of `PLAN_COLUMNS`, and
    where the rows have ``plan`` (retrieved templates) how many templates share it."""
    out: dict[str, dict[str, Any]] = {}
    for plan in sorted({r["video_plan"] for r in rows if r.get("video_plan")}):
        rs = [r for r in rows if r.get("video_plan") == plan]
        out[plan] = {"videos": len(rs), **{k: _mean([r.get(k) for r in rs]) for k in PLAN_COLUMNS}}
        if any("plan" in r for r in rs):
            out[plan]["template_right"] = sum(bool(r.get("plan", {}).get("right")) for r in rs)
    return out


def _mean(vals: list) -> float | None:
    v = [x for x in vals if x is not None and np.isfinite(x)]
    return float(np.mean(v)) if v else None


def markdown_table(res: dict[str, Any]) -> str:
    """The summary (one row per ablation) and the per-video rows, as markdown."""
    head = (
        "| ablation | videos | 2D mask IoU | novel-view IoU | held-out PSNR dB | mIoU | mCham | Joint (CD-J2J) "
        "| Skinning | Re-animation | torn edges | wall s |"
    )
    camera = (
        "known (each video's own camera rotations)" if res.get("known_camera") else "estimated from the masks"
    )
    lines = [f"Camera motion: {camera}."]
    if res.get("own_template"):
        lines.append("Template: each video's own asset (no retrieval).")
    if res.get("overrides"):
        lines.append(f"Config overrides: {json.dumps(res['overrides'], sort_keys=True)}.")
    lines.append(
        "Novel-view IoU: mask IoU from held-out cameras (+90 deg azimuth, +35 deg elevation) after "
        "mIoU's alignment (`zooctl.fit.metrics`); n/a for videos made without them."
    )
    lines.append(
        "Held-out PSNR: the fit's colours rendered unlit from those cameras against what they saw, on "
        "the pixels both cover (`zooctl.benchdata.appearance`); n/a for videos made without "
        "`--appearance textured`."
    )
    lines += ["", head, "|" + "---|" * 12]

    def f(x, k=""):
        if x is None:
            return "n/a" if k in ("novel_view_iou", "view_psnr") else "-"
        return f"{x:.2f}" if k == "view_psnr" else f"{x:.3f}"

    for a, s in res["summary"].items():
        lines.append(f"| {a} | {s['videos']} | " + " | ".join(f(s[k], k) for k in COLUMNS) + " |")
    for a, s in res["summary"].items():
        if "plan" in s:
            p = s["plan"]
            lines.append(
                f"\nRight body plan ({a}): {p['top1']} at retrieval's top-1, {p['tried']} among the "
                f"candidates tried, {p['template']} after the trials, of {p['labelled']} labelled videos "
                f"({p['answerable']} with another asset of their plan in the bank)."
            )
    for a, s in res["summary"].items():
        if s.get("by_plan"):
            lines += _plan_table(a, s["by_plan"], f)
    lines += [
        "",
        "| video | ablation | template | 2D mask IoU | novel-view IoU | held-out PSNR | mIoU | mCham | Joint "
        "| Skinning | Re-anim. | torn | wall s |",
        "|" + "---|" * 13,
    ]
    for r in res["rows"]:
        if "error" in r:
            lines.append(f"| {r['video']} | {r['ablation']} | error: {r['error']} |" + " |" * 10)
        else:
            right = r.get("plan", {}).get("right")
            mark = "" if right is None else (" (right plan)" if right else " (other plan)")
            lines.append(
                f"| {r['video']} | {r['ablation']} | {r['template']}{mark} | "
                + " | ".join(f(r.get(k), k) for k in COLUMNS)
                + " |"
            )
    return "\n".join(lines) + "\n"


def _plan_table(ablation: str, by_plan: dict[str, dict[str, Any]], f) -> list[str]:
    """Markdown lines: the summary by the videos' body plan, the lowest novel view first."""
    retrieved = any("template_right" in p for p in by_plan.values())
    head = "| body plan | videos | 2D mask IoU | novel-view IoU | mIoU |" + (
        " template of that plan |" if retrieved else ""
    )
    lines = ["", f"By the video's body plan ({ablation}):", "", head, "|" + "---|" * (6 if retrieved else 5)]
    order = sorted(
        by_plan, key=lambda k: (by_plan[k]["novel_view_iou"] is None, by_plan[k]["novel_view_iou"] or 0, k)
    )
    for plan in order:
        p = by_plan[plan]
        cells = [plan, str(p["videos"])] + [f(p[k], k) for k in PLAN_COLUMNS]
        if retrieved:
            cells.append(f"{p.get('template_right', 0)} of {p['videos']}")
        lines.append("| " + " | ".join(cells) + " |")
    return lines
