"""Analysis by synthesis on the shared real videos: does a fit's reprojection make better masks?

For each DAVIS video in ``../shared/data/videos``: the fit ``zooctl fit DIR --masks auto`` runs
(the video stored with the automatic no-box masks, template retrieval and its trials, the winner
fitted on; no outputs), then `zooctl.fit.refine_masks.refine_and_refit`: the first fit's
reprojection re-segments every frame, one fit of the same template runs on the refined masks.
Measured against the DAVIS ground truth: J of the automatic masks and of the refined masks, and
the fit's silhouette IoU (its exported character through its camera) before and after; also each
fit's IoU against the masks it was fitted on. Written: ``OUT/refine_masks.md`` (the table),
``OUT/results/VIDEO.json``, ``OUT/fits/VIDEO/refined_masks.npz`` and ``OUT/overlays/VIDEO.png``.

The re-segmentation's radii are fixed beforehand (`zooctl.video.shape_prior.PriorOptions`); what
other radii would have given is measured offline from each video's saved prior (no refit) and
chosen leave-one-video-out (``--grid``), and whether to refine at all is chosen leave-one-video-out
too, so the table shows in-sample and leave-one-out numbers side by side.

    OMP_NUM_THREADS=1 .venv/bin/python bench/refine_masks.py [--videos dog bear] [--out DIR]

One fit at a time; a video whose result is in ``OUT/results/VIDEO.json`` is not fitted again.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "bench"))
VIDEOS = REPO.parent / "shared" / "data" / "videos"
SEQUENCES = ("blackswan", "dog", "cows", "bear", "elephant", "mallard-water", "dog-agility")
# the radii measured offline besides the defaults (each varied alone)
GRID = {"core": (0.025, 0.05, 0.1), "band": (0.05, 0.1, 0.2)}


def cpu_seconds() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def seed_bank(store: Path) -> None:
    if (store / "bank").is_dir() and any((store / "bank").iterdir()):
        return
    cmd = [sys.executable, "-m", "zooctl", "--store", str(store), "bank", "seed"]
    subprocess.run(cmd, check=True, cwd=REPO, capture_output=True)


def stored_masks(store: Path, name: str) -> tuple[np.ndarray, object]:
    """The stored video's (automatic) masks (T, H, W) bool and its frames."""
    from zooctl.fit.job import load_source

    v = load_source(name, store, None, None)
    return np.stack([np.asarray(v.masks[i], bool) for i in range(v.num_frames)]), v.frames


def fit_one(seq: str, store: Path, out: Path, preset_name: str) -> dict:
    """The fit `zooctl fit DIR --masks auto` runs (the video stored with the automatic masks, the
    retrieved template's trials, the winner fitted on), then `refine_and_refit`; the masks and
    silhouettes against the ground truth."""
    import torch
    from video import load_truth

    from zooctl.fit.config import preset
    from zooctl.fit.job import load_source
    from zooctl.fit.refine_masks import load_refined, mask_iou, refine_and_refit
    from zooctl.fit.run import fit_video
    from zooctl.fit.template import select_template
    from zooctl.store.bank import Bank
    from zooctl.video.mask_quality import per_frame_j

    torch.set_num_threads(1)
    cfg = preset(preset_name)
    t0, c0 = time.perf_counter(), cpu_seconds()
    video = load_source(str(VIDEOS / seq), store, "auto", cfg.max_frames)
    asset, _, state, _ = select_template(Bank.open(store), None, video, cfg)
    first = fit_video(video, asset, cfg, None, None, state)
    first_wall = time.perf_counter() - t0
    refit, info = refine_and_refit(first, out / "fits" / seq)
    wall, cpu = time.perf_counter() - t0, cpu_seconds() - c0
    saved = load_refined(Path(info["file"]))
    auto = np.stack([np.asarray(video.masks[i], bool) for i in range(video.num_frames)])
    truth = load_truth(seq, auto.shape)
    (out / "fits" / seq / "fit.json").write_text(
        json.dumps({"stored_video": video.source.removeprefix("video:"), "template": asset.name, **info})
    )

    def j(m):
        return float(per_frame_j(m, truth).mean())

    return {
        "video": seq,
        "frames": len(auto),
        "template": asset.name,
        "J_auto": j(auto),
        "J_refined": j(saved["masks"]),
        "fit_iou_truth_before": j(saved["prior"]),
        "fit_iou_truth_after": j(saved["refit"]),
        "fit_iou_own_before": info["before"]["mask_iou"],
        "fit_iou_own_after": mask_iou(saved["refit"], saved["masks"]),
        "fit_iou_auto_after": info["after"]["mask_iou_original"],
        "refine_s": info["seconds"]["refine"],
        "refit_s": info["seconds"]["refit"],
        "first_fit_wall_s": first_wall,
        "total_wall_s": wall,
        "total_cpu_s": cpu,
    }


def offline_grid(seq: str, store: Path, out: Path) -> dict:
    """J of the refined masks at each grid radius (the rest at its default), from the saved prior:
    {label: J}."""
    from video import load_truth

    from zooctl.fit.refine_masks import REFINED_FILE, load_refined
    from zooctl.video.mask_quality import per_frame_j
    from zooctl.video.shape_prior import PriorOptions, refine_masks

    saved = load_refined(out / "fits" / seq / REFINED_FILE)
    rec = json.loads((out / "fits" / seq / "fit.json").read_text())
    auto, frames = stored_masks(store, rec["stored_video"])
    truth = load_truth(seq, (len(auto), *auto.shape[1:]))
    scores = {}
    for k, values in GRID.items():
        for v in values:
            opts = dataclasses.replace(PriorOptions(), **{k: v})
            label = label_of(opts)
            if label in scores:
                continue
            masks = refine_masks(frames, auto, saved["prior"], opts)
            scores[label] = float(per_frame_j(masks, truth).mean())
    return scores


def overlays(seq: str, store: Path, out: Path) -> None:
    """``overlays/VIDEO.png``: six frames, the automatic mask (green) against the truth (magenta),
    and beside it the same frames with the refined mask (green) and the first fit's
    reprojection (its outline in yellow)."""
    import cv2
    from video import load_truth
    from video_quality import overlay_sheet

    from zooctl.fit.refine_masks import REFINED_FILE, load_refined

    path = out / "overlays" / f"{seq}.png"
    if path.exists():
        return
    saved = load_refined(out / "fits" / seq / REFINED_FILE)
    auto, frames = stored_masks(
        store, json.loads((out / "fits" / seq / "fit.json").read_text())["stored_video"]
    )
    truth = load_truth(seq, (len(auto), *auto.shape[1:]))
    frames = np.stack([np.array(frames[i], np.uint8) for i in range(len(auto))])
    with_prior = frames.copy()
    for i in range(len(frames)):
        c, _ = cv2.findContours(
            saved["prior"][i].astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE
        )
        cv2.drawContours(with_prior[i], c, -1, (255, 255, 0), 2, cv2.LINE_AA)
    overlay_sheet(out / "overlays" / f"{seq}-auto.png", frames, auto, truth)
    overlay_sheet(out / "overlays" / f"{seq}-refined.png", with_prior, saved["masks"], truth)
    a = cv2.imread(str(out / "overlays" / f"{seq}-auto.png"))
    b = cv2.imread(str(out / "overlays" / f"{seq}-refined.png"))
    cv2.imwrite(str(path), np.hstack([a, np.full((a.shape[0], 8, 3), 255, np.uint8), b]))
    for extra in ("auto", "refined"):
        (out / "overlays" / f"{seq}-{extra}.png").unlink()


def label_of(opts) -> str:
    return f"core={opts.core:g},band={opts.band:g}"


def table(results: dict, grid: dict | None) -> str:
    """Markdown: per video the masks' J and the fit's IoU against the truth, without and with the
    refinement, and leave-one-out choices: refining or not (picked on six videos, scored on the
    seventh), and with ``grid`` the radii."""
    from zooctl.video.mask_quality import leave_one_out
    from zooctl.video.shape_prior import PriorOptions

    seqs = [s for s in SEQUENCES if s in results]

    def choice(before: str, after: str):
        scores = {"off": {s: results[s][before] for s in seqs}, "on": {s: results[s][after] for s in seqs}}
        return leave_one_out(scores, prefer="off") if len(seqs) >= 2 else None

    loo_j, loo_fit = choice("J_auto", "J_refined"), choice("fit_iou_truth_before", "fit_iou_truth_after")
    loo_radii = None
    if grid and len(seqs) >= 2 and all(s in grid for s in seqs):
        by_label = {lab: {s: grid[s][lab] for s in seqs} for lab in grid[seqs[0]]}
        loo_radii = leave_one_out(by_label, prefer=label_of(PriorOptions()))
    head = ["video", "frames", "template", "J auto", "J refined", "J, refine or not leave-one-out (picked)"]
    if loo_radii is not None:
        head += ["J refined, best radii on all (in-sample)", "J refined, radii leave-one-out (picked)"]
    head += [
        "fit IoU vs truth, first fit",
        "refit",
        "fit IoU, refine or not leave-one-out (picked)",
        "fit IoU vs its own masks, first fit",
        "refit",
        "refine s",
        "refit s",
        "total wall s (CPU s)",
    ]
    rows = ["| " + " | ".join(head) + " |", "|---|---:|---|" + "---:|" * (len(head) - 3)]

    def picked(loo, s):
        return "-" if loo is None else f"{loo.held_out[s]:.3f} ({loo.picked[s]})"

    for s in seqs:
        r = results[s]
        cells = [s, str(r["frames"]), r["template"], f"{r['J_auto']:.3f}", f"{r['J_refined']:.3f}"]
        cells.append(picked(loo_j, s))
        if loo_radii is not None:
            cells += [f"{loo_radii.in_sample[s]:.3f}", picked(loo_radii, s)]
        cells += [f"{r['fit_iou_truth_before']:.3f}", f"{r['fit_iou_truth_after']:.3f}", picked(loo_fit, s)]
        cells += [f"{r['fit_iou_own_before']:.3f}", f"{r['fit_iou_own_after']:.3f}"]
        cells += [
            f"{r['refine_s']:.0f}",
            f"{r['refit_s']:.0f}",
            f"{r['total_wall_s']:.0f} ({r['total_cpu_s']:.0f})",
        ]
        rows.append("| " + " | ".join(cells) + " |")

    def mean(k):
        return f"{float(np.mean([results[s][k] for s in seqs])):.3f}"

    def held(loo):
        return "-" if loo is None else f"**{loo.held_out_mean:.3f}**"

    cells = [f"**mean of {len(seqs)}**", str(sum(results[s]["frames"] for s in seqs)), ""]
    cells += [f"**{mean('J_auto')}**", f"**{mean('J_refined')}**", held(loo_j)]
    if loo_radii is not None:
        cells += [f"{loo_radii.in_sample_mean:.3f} ({loo_radii.best})", held(loo_radii)]
    cells += [mean("fit_iou_truth_before"), mean("fit_iou_truth_after"), held(loo_fit)]
    cells += [mean("fit_iou_own_before"), mean("fit_iou_own_after")]
    cells += [
        f"{float(np.mean([results[s][k] for s in seqs])):.0f}"
        for k in ("refine_s", "refit_s", "total_wall_s")
    ]
    cells[-1] += f" ({float(np.mean([results[s]['total_cpu_s'] for s in seqs])):.0f})"
    rows.append("| " + " | ".join(cells) + " |")
    return "\n".join(rows) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--videos", nargs="*", default=list(SEQUENCES))
    ap.add_argument("--out", type=Path, default=REPO / "bench" / "out" / "refine_masks")
    ap.add_argument("--preset", default="fast")
    ap.add_argument(
        "--grid", action="store_true", help="also the offline radii grid (GrabCut again per radius)"
    )
    args = ap.parse_args()
    if not VIDEOS.is_dir():
        sys.exit(f"no shared videos at {VIDEOS}")
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    out = args.out.resolve()
    store = out / "store"
    seed_bank(store)
    results, grid = {}, {}
    for seq in args.videos:
        path = out / "results" / f"{seq}.json"
        if path.exists():
            results[seq] = json.loads(path.read_text())
        else:
            results[seq] = fit_one(seq, store, out, args.preset)
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(results[seq], indent=1))
        r = results[seq]
        print(
            f"{seq:14s} J auto {r['J_auto']:.3f} refined {r['J_refined']:.3f}; fit IoU vs truth "
            f"{r['fit_iou_truth_before']:.3f} -> {r['fit_iou_truth_after']:.3f}; {r['total_wall_s']:.0f} s",
            file=sys.stderr,
            flush=True,
        )
        overlays(seq, store, out)
        if args.grid:
            gpath = out / "grid" / f"{seq}.json"
            if gpath.exists():
                grid[seq] = json.loads(gpath.read_text())
            else:
                grid[seq] = offline_grid(seq, store, out)
                gpath.parent.mkdir(parents=True, exist_ok=True)
                gpath.write_text(json.dumps(grid[seq], indent=1))
            print(f"  radii: {grid[seq]}", file=sys.stderr, flush=True)
    md = table(results, grid or None)
    (out / "refine_masks.md").write_text(md)
    (out / "refine_masks.json").write_text(json.dumps({"results": results, "grid": grid}, indent=1))
    print(md)


if __name__ == "__main__":
    main()
