"""The camera's turn read from the background (`zooctl.video.camera_motion`) against the truth.

    python bench/camera_motion.py DIR [--json OUT.json]

DIR: a `zooctl bench make` folder (``--background world`` for a scene that turns with the
camera; a still one reads as a camera at rest). For each video: the true turn of its camera over
the video, the turn read, the worst frame's error (degrees, each frame's rotation from the first
against the truth's), the pairs of frames read, and the seconds the read took (one thread).
The benchmark camera's own focal is used, as `bench run` gives it to the fit.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from zooctl.geometry import rotation_angle_deg
from zooctl.video.camera_motion import background_motion


def main() -> None:
    import torch
    from _util import machine

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("folder", type=Path)
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    torch.set_num_threads(1)
    rows = []
    print(f"machine: {machine()}")
    print("| video | true turn (deg) | read (deg) | worst frame error (deg) | pairs read | seconds |")
    print("|---|---:|---:|---:|---:|---:|")
    for d in sorted(p for p in a.folder.iterdir() if (p / "video.npz").is_file()):
        with np.load(d / "video.npz") as z:
            frames, masks, K, C = z["frames"], z["masks"], z["intrinsics"], z["gt_cam_rotation"]
        t = time.perf_counter()
        m = background_motion(frames, masks, float(K[0]), (float(K[2]), float(K[3])))
        sec = time.perf_counter() - t
        truth = C @ C[0].T
        worst = max(rotation_angle_deg(m.rotations[i] @ truth[i].T) for i in range(len(C)))
        row = {
            "video": d.name,
            "true_turn_deg": round(max(rotation_angle_deg(R) for R in truth), 2),
            "read_turn_deg": round(m.span_deg(), 2),
            "worst_error_deg": round(worst, 3),
            "pairs_read": int(m.known.sum()),
            "pairs": int(len(m.known)),
            "seconds": round(sec, 3),
        }
        rows.append(row)
        print(
            f"| {d.name} | {row['true_turn_deg']:.1f} | {row['read_turn_deg']:.1f} | {worst:.3f} "
            f"| {row['pairs_read']}/{row['pairs']} | {sec:.2f} |",
            flush=True,
        )
    if rows:
        print(
            f"{len(rows)} videos: worst frame error max {max(r['worst_error_deg'] for r in rows):.3f} deg, "
            f"median {np.median([r['worst_error_deg'] for r in rows]):.3f}; pairs read "
            f"{sum(r['pairs_read'] for r in rows)}/{sum(r['pairs'] for r in rows)}; "
            f"median {np.median([r['seconds'] for r in rows]):.2f} s a video"
        )
    if a.json:
        a.json.write_text(json.dumps({"machine": machine(), "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
