"""What a statue scores: each benchmark video's own animal frozen in its first frame's pose.

    python bench/statue.py DIR [DIR ...] [--json OUT.json]

Issue 50 measured that the right animal, frozen in its frame-0 pose and left where it stood,
scores a novel-view IoU of about 0.45 on its held-out harness, higher than the fits did then. This
is the same baseline on `zooctl bench make` videos, scored as `zooctl bench run` scores a fit
(`zooctl.fit.metrics`): the true surface of frame 0, fixed in the world, seen on the evaluated
frames (four, spread over the video) by the input camera, by both held-out cameras (+90 degrees
azimuth, +35 elevation), and compared in each frame's camera with the true surface (mIoU with the
line search over scale). It reads only each video's ``video.npz``; no fit runs. A fit whose novel
view is under its video's statue is further from the animal, seen from the side, than an animal
that never moved.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from zooctl.benchdata.run import bench_videos
from zooctl.fit.metrics import scale_line_search, surface_samples, world_silhouettes
from zooctl.geometry import silhouette_iou


def statue_scores(video: Path, frames: int = 4) -> dict:
    d = np.load(video / "video.npz")
    gv, faces, K = d["gt_vertices"], d["gt_faces"], d["intrinsics"]
    T, H, W = d["masks"].shape
    sel = np.unique(np.linspace(0, T - 1, min(frames, T)).astype(int))
    statue = np.repeat(gv[:1], len(sel), 0)  # frame 0's surface, where it stood, at every frame
    R, t = d["gt_cam_rotation"][sel], d["gt_cam_translation"][sel]
    row = {"video": video.name, "frames_evaluated": [int(s) for s in sel]}
    seen = silhouette_iou(world_silhouettes(statue, faces, K, R, t, H, W), d["masks"][sel])
    row["input_view_iou_per_frame"] = [round(float(x), 4) for x in seen]
    row["input_view_iou"] = float(np.nanmean(seen))
    per_view, per_frame = [], []
    for c in range(d["gt_view_masks"].shape[0]):
        sil = world_silhouettes(
            statue, faces, K, d["gt_view_rotation"][c, sel], d["gt_view_translation"][c, sel], H, W
        )
        ious = silhouette_iou(sil, d["gt_view_masks"][c, sel])
        per_frame.append([round(float(x), 4) for x in ious])
        per_view.append(float(np.nanmean(ious)))
    row["novel_view_iou_per_view"] = per_view
    row["novel_view_iou_per_frame"] = per_frame
    row["novel_view_iou"] = float(np.mean(per_view))
    mious = []
    for i, s in enumerate(sel):
        truth = surface_samples(gv[s] @ R[i].T + t[i], faces)
        pred = surface_samples(gv[0] @ R[i].T + t[i], faces)
        mious.append(scale_line_search(pred, truth)[1])
    row["miou"] = float(np.mean(mious))
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", type=Path, nargs="+")
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    rows = [statue_scores(v) for f in args.folders for v in bench_videos(f)]
    print("| video | input view | novel view | mIoU |\n|---|---:|---:|---:|")
    for r in rows:
        print(f"| {r['video']} | {r['input_view_iou']:.3f} | {r['novel_view_iou']:.3f} | {r['miou']:.3f} |")
    means = {k: float(np.mean([r[k] for r in rows])) for k in ("input_view_iou", "novel_view_iou", "miou")}
    print(
        f"| mean of {len(rows)} | {means['input_view_iou']:.3f} | {means['novel_view_iou']:.3f} | {means['miou']:.3f} |"
    )
    if args.json:
        args.json.write_text(json.dumps({"rows": rows, "means": means}, indent=1))


if __name__ == "__main__":
    main()
