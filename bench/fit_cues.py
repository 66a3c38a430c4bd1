"""Fit configurations compared per video, and which one to use chosen leave-one-video-out.

    python bench/fit_cues.py NAME=RUN.json [NAME=RUN.json ...] [--metric novel_view_iou]
        [--guard mask_iou=0.005 ...]

Each RUN.json is the output of `zooctl bench run DIR --json` (one ablation, the same videos) for
one configuration, e.g. ``--config`` files switching a loss term on; the first is the baseline.
Prints a markdown table for BENCHMARKS.md: per video and on the mean, each configuration's input
mask IoU, novel-view IoU, mIoU and Joint error; then the leave-one-video-out choice: for each
video, the configuration with the best mean ``--metric`` on the other videos (the baseline on a
tie), scored on that video; for every other configuration alone against the baseline (on/off)
and among all of them. In-sample beside it: the configuration best on all videos. A ``--guard
METRIC=MARGIN`` leaves out of a choice every configuration whose mean METRIC on the choosing
videos is worse than the baseline's by more than MARGIN (e.g. the least torn surface that costs
at most 0.005 of input view). Rows with ``surface_tear`` or ``view_psnr`` (a textured benchmark's
held-out colour error, dB) add them as columns.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

METRICS = (("mask_iou", "input IoU"), ("novel_view_iou", "novel view"), ("miou", "mIoU"), ("joint", "Joint"))
LOWER_IS_BETTER = {"joint", "mcham", "surface_tear"}


def load(spec: str) -> tuple[str, dict[str, dict]]:
    name, path = spec.split("=", 1)
    rows = json.loads(Path(path).read_text())["rows"]
    return name, {r["video"]: r for r in rows if "error" not in r}


def score(rows: dict[str, dict], videos: list[str], metric: str) -> float:
    sign = -1.0 if metric in LOWER_IS_BETTER else 1.0
    return sign * float(np.mean([rows[v][metric] for v in videos]))


def choose(
    runs: dict[str, dict[str, dict]],
    names: list[str],
    videos: list[str],
    metric: str,
    guards: dict[str, float] | None = None,
) -> str:
    """The configuration of ``names`` best on ``videos`` by ``metric``, among those within each
    guard's margin of the first (the baseline, which is also the choice on a tie)."""

    def allowed(n: str) -> bool:
        return all(
            score(runs[n], videos, k) >= score(runs[names[0]], videos, k) - m
            for k, m in (guards or {}).items()
        )

    best = names[0]
    for n in names[1:]:
        if allowed(n) and score(runs[n], videos, metric) > score(runs[best], videos, metric) + 1e-9:
            best = n
    return best


def loo(runs, names, videos, metric, guards=None, metrics=METRICS) -> tuple[dict[str, str], dict[str, float]]:
    """Per held-out video the configuration chosen on the others, and the means of every metric
    of those choices."""
    picked = {v: choose(runs, names, [u for u in videos if u != v], metric, guards) for v in videos}
    means = {k: float(np.mean([runs[picked[v]][v][k] for v in videos])) for k, _ in metrics}
    return picked, means


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("runs", nargs="+", help="NAME=RUN.json, the baseline first")
    ap.add_argument("--metric", default="novel_view_iou", help="what the leave-one-out choice optimises")
    ap.add_argument(
        "--guard",
        action="append",
        default=[],
        metavar="METRIC=MARGIN",
        help="no configuration worse than the baseline on METRIC by more than MARGIN (repeatable)",
    )
    args = ap.parse_args()
    runs = dict(load(s) for s in args.runs)
    names = list(runs)
    guards = {k: float(m) for k, m in (g.split("=", 1) for g in args.guard)}
    videos = sorted(set.intersection(*(set(r) for r in runs.values())))
    if len(videos) < 2:
        raise SystemExit("the runs share fewer than two fitted videos: nothing to leave out")
    extra = (("surface_tear", "torn"), ("view_psnr", "held-out PSNR"))
    metrics = METRICS + tuple(
        (k, lab) for k, lab in extra if all(runs[n][v].get(k) is not None for n in names for v in videos)
    )
    head = "| video | " + " | ".join(f"{lab}: {' / '.join(names)}" for _, lab in metrics) + " |"
    print(head)
    print("|---" * (1 + len(metrics)) + "|")
    for v in videos + ["mean"]:
        cells = []
        for k, _ in metrics:
            vals = [
                runs[n][v][k] if v != "mean" else float(np.mean([runs[n][u][k] for u in videos]))
                for n in names
            ]
            cells.append(" / ".join(f"{x:.2f}" if k == "view_psnr" else f"{x:.3f}" for x in vals))
        print(f"| {v} | " + " | ".join(cells) + " |")
    within = "".join(f", {k} at most {m} below the baseline" for k, m in guards.items())
    print(f"\nchoice by {args.metric}{within}, {len(videos)} videos:\n")
    print(
        "| choice among | in-sample (best on all) | "
        + " | ".join(f"{lab} in / loo" for _, lab in metrics)
        + " | picked per held-out video |"
    )
    print("|---" * (3 + len(metrics)) + "|")
    sets = [[names[0], n] for n in names[1:]] + ([names] if len(names) > 2 else [])
    for group in sets:
        best = choose(runs, group, videos, args.metric, guards)
        picked, means = loo(runs, group, videos, args.metric, guards, metrics)
        ins = {k: float(np.mean([runs[best][v][k] for v in videos])) for k, _ in metrics}
        cells = " | ".join(f"{ins[k]:.3f} / {means[k]:.3f}" for k, _ in metrics)
        per = ", ".join(f"{v} {picked[v]}" for v in videos)
        print(f"| {', '.join(group)} | {best} | {cells} | {per} |")


if __name__ == "__main__":
    main()
