"""Benchmark videos fitted the way a user fits a video: through the video store's own masks and flow.

    ZOOCTL_STORE=STORE python bench/user_path.py DIR [--own-template] [--config C.json] [--limit N]
        [--masks truth] [--focal truth] [--json OUT.json]

`zooctl bench run` fits each video against the benchmark's exact masks and flow. A user's video
has neither: `zooctl video add` segments it (no box) and estimates its flow, and every fit
inherits what they get wrong. Here each `zooctl bench make` video's ``video.mp4`` (H.264, as a
camera would give it) is added with `zooctl video add` (skipped when the store has it), then
fitted from the store as `zooctl fit` does (retrieval and the template trials, the video's own
asset excluded; or its own rig with ``--own-template``) and scored against the benchmark's truth
(`fit_job`'s ``truth``). Per video: the stored masks' J against the true masks, the fit's input
view against the true masks (``mask_iou_truth``) and against the masks it read, and the 3D
metrics of `zooctl bench run`. ``--json`` writes rows in `zooctl bench run --json`'s shape
(``mask_iou`` is the input view against the truth), so `bench/fit_cues.py` compares the two runs.

What the user path loses, one part at a time: ``--masks truth`` adds the video with the
benchmark's true masks as the user's own (`video add --masks`; the flow is still estimated),
``--focal truth`` gives the fit the benchmark camera's focal (`camera.focal`) instead of what
a fit does when no lens is known (`zooctl.fit.focal`: ``camera.focal_guess``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from zooctl.benchdata.run import bench_videos
from zooctl.fit.config import FitConfig, preset
from zooctl.fit.inputs import load_fit_video
from zooctl.fit.job import fit_job, load_source
from zooctl.paths import default_store
from zooctl.video.mask_quality import per_frame_j


def stored_name(video: Path, true_masks: bool = False) -> str:
    return f"bench-{video.name}{'-truemasks' if true_masks else ''}".lower()


def add_video(video: Path, root: Path, true_masks: bool = False) -> None:
    """`zooctl video add` of the benchmark's mp4, as a user runs it (no box, every default), or
    with the benchmark's masks as the user's own."""
    from PIL import Image

    from zooctl.store.videos import VideoStore

    name = stored_name(video, true_masks)
    if VideoStore.open(root).exists(name):
        return
    cmd = [sys.executable, "-m", "zooctl", "video", "add", str(video / "video.mp4"), "--name", name]
    with tempfile.TemporaryDirectory() as tmp:
        if true_masks:
            for i, m in enumerate(load_fit_video(video).masks):
                Image.fromarray(m.astype(np.uint8) * 255).save(Path(tmp) / f"{i:05d}.png")
            cmd += ["--masks", tmp]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path)
    ap.add_argument("--own-template", action="store_true")
    ap.add_argument("--config", type=Path)
    ap.add_argument("--limit", type=int)
    ap.add_argument("--json", type=Path)
    ap.add_argument("--masks", choices=("auto", "truth"), default="auto")
    ap.add_argument("--focal", choices=("estimated", "truth"), default="estimated")
    args = ap.parse_args()
    root = default_store()
    vids = bench_videos(args.folder)[: args.limit]
    rows = []
    for v in vids:
        own = json.loads((v / "meta.json").read_text())["asset"]
        t0 = time.perf_counter()
        true_masks = args.masks == "truth"
        add_video(v, root, true_masks)
        t_add = time.perf_counter() - t0
        truth = load_fit_video(v)
        cfg = preset("fast")
        if args.config:
            cfg = FitConfig.from_dict(json.loads(args.config.read_text()), cfg)
        if args.focal == "truth":
            cfg.camera.focal = float(truth.intrinsics[0])
        t0 = time.perf_counter()
        rec = fit_job(
            stored_name(v, true_masks),
            root,
            cfg,
            name=f"user-{v.name}-{args.masks}-{args.focal}".lower(),
            template=own if args.own_template else None,
            exclude=set() if args.own_template else {own},
            outputs=("loss",),
            replace=True,
            truth=v,
        )
        m = rec["metrics"]  # the fit has checked that the stored video's frames are the truth's
        stored = load_source(stored_name(v, true_masks), root, None, None)
        j = float(per_frame_j(np.asarray(stored.masks), truth.masks).mean())
        row = {
            "video": v.name,
            "template": rec["template"],
            "mask_j": j,
            "mask_iou": m.get("mask_iou_truth"),
            "mask_iou_read": m.get("mask_iou"),
            **{
                k: m.get(k)
                for k in ("novel_view_iou", "miou", "mcham", "joint", "surface_tear", "tilt_error")
            },
            "add_s": t_add,
            "wall_s": time.perf_counter() - t0,
        }
        rows.append(row)
        print(json.dumps({k: round(x, 4) if isinstance(x, float) else x for k, x in row.items()}), flush=True)
    keys = ("mask_j", "mask_iou", "mask_iou_read", "novel_view_iou", "miou", "joint")
    print("| video | template | " + " | ".join(keys) + " |")
    print("|---|---|" + "---:|" * len(keys))
    for r in rows + [{"video": "mean", "template": "", **{k: np.mean([r[k] for r in rows]) for k in keys}}]:
        print(f"| {r['video']} | {r['template']} | " + " | ".join(f"{r[k]:.3f}" for k in keys) + " |")
    if args.json:
        meta = {"own_template": args.own_template, "masks": args.masks, "focal": args.focal}
        args.json.write_text(json.dumps({"rows": rows, **meta}, indent=1))


if __name__ == "__main__":
    main()
