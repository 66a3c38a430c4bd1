"""How much of a fit's novel view its orientation costs: each stored own-rig fit of a benchmark
video scored as fitted, and again with every evaluated frame's orientation, scale and place given.

    python bench/orientation.py --store STORE [FIT ...] [--json OUT]

For fits of `zooctl bench run --own-template` (the fitted model's vertices correspond one to one
with the truth's), in the store STORE (default: every fit there whose template has the truth's
vertex count). Each fit is reloaded from its ``state.pt`` (the finished state: no iteration runs)
and, on the frames `zooctl.fit.metrics.evaluate_fit` evaluates:

- ``novel``: the novel-view IoU as `bench run` reports it (the line-search scale);
- ``novel_orientation_given``: the same cameras and truth, the fitted vertices first moved by the
  similarity (rotation, scale, translation; Procrustes) that best maps them onto the truth's in the
  input camera's frame: what is left is the articulation's error;
- ``rotation_error_deg``: that similarity's rotation, per frame: how far the fit's orientation is
  from the truth's.

One JSON line a fit, then the means (BENCHMARKS.md, "Where the own rig's novel view is lost now").
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import finish_lines, stored_bench_fits, stored_fits_parser  # noqa: E402


def similarity(p: np.ndarray, g: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """(s, R, t) minimising |s R p + t - g|^2 over corresponding points p, g (N, 3)."""
    mp, mg = p.mean(0), g.mean(0)
    P, G = p - mp, g - mg
    U, S, Vt = np.linalg.svd(G.T @ P)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    s = float((S * np.diag(D)).sum() / max((P**2).sum(), 1e-12))
    return s, R, mg - s * R @ mp


def main() -> None:
    args = stored_fits_parser(__doc__).parse_args()

    from zooctl.fit import metrics

    lines, rows = [], []
    for name, _, res in stored_bench_fits(args.store, args.fits):
        video = res.video
        if res.scene.model.num_vertices != video.gt["vertices"].shape[1]:
            print(f"{name}: its template is not the video's own rig; skipped", file=sys.stderr)
            continue
        scores = metrics.evaluate_fit(res, reanimate_iters=1)
        sel = np.asarray(scores["frames_evaluated"])
        pred, _ = metrics._camera_frame_pred(res, sel)
        moved, errors = [], []
        for i, t in enumerate(sel):
            truth, _ = metrics._camera_frame_gt(res, int(t))
            s, R, tr = similarity(pred[i], truth)
            moved.append(s * pred[i] @ R.T + tr)
            errors.append(math.degrees(math.acos(float(np.clip((np.trace(R) - 1) / 2, -1.0, 1.0)))))
        given = metrics.novel_view_iou(res, sel, np.stack(moved), np.ones(len(sel)))
        row = {
            "fit": name,
            "novel": scores["novel_view_iou"],
            "novel_orientation_given": metrics._finite_mean(given) if given else None,
            "rotation_error_deg": [round(e, 1) for e in errors],
            "frames": scores["frames_evaluated"],
        }
        rows.append(row)
        lines.append(json.dumps(row))
        print(lines[-1], flush=True)
    if not rows:
        sys.exit(f"error: no finished own-rig benchmark fits in {args.store}")
    errs = np.array([e for r in rows for e in r["rotation_error_deg"]])
    summary = {
        "fits": len(rows),
        "novel": float(np.mean([r["novel"] for r in rows])),
        "novel_orientation_given": float(np.mean([r["novel_orientation_given"] for r in rows])),
        "rotation_error_deg_median": float(np.median(errs)),
        "frames_over_30_deg": int((errs > 30).sum()),
        "frames": len(errs),
    }
    finish_lines(lines, summary, args.json)


if __name__ == "__main__":
    main()
