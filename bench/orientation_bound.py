"""What a fit's novel view would be with its orientation mended, for any template: each stored
benchmark fit scored as fitted, with every evaluated frame's body mirrored in depth, and turned
to the rotation that best lays it on the truth's surface.

    python bench/orientation_bound.py --store STORE [FIT ...] [--frames 4] [--json OUT]

For fits of `zooctl bench run` (any template: nothing needs the truth's vertices to correspond),
in the store STORE (default: every finished fit there). Each fit is reloaded from its ``state.pt``
(the finished state: no iteration runs) and scored on the frames `zooctl.fit.metrics.evaluate_fit`
evaluates (``--frames``: how many; the benchmark's 4 by default) by the novel-view IoU as `bench
run` reports it, then with each frame's fitted vertices mirrored in depth through their centre
and moved along their rays so the input camera sees exactly the same silhouette (``z' = 2 z_c -
z``, ``x' = x z'/z``, ``y' = y z'/z``, with each frame's own scale): the view a silhouette cannot
tell from the fit's. Per frame the mean over the held-out cameras is compared:

- ``novel``: as fitted; ``novel_mirrored``: every frame mirrored;
- ``novel_better``: each frame as fitted or mirrored, whichever the held-out cameras prefer (an
  oracle: what telling the two views apart could win at most);
- ``flipped_frames``: frames the mirror scores more than 0.05 higher: frames the fit most likely
  sees from the wrong side;
- ``novel_rotated``: each frame's body (at its scale) turned about its centre by the rotation
  that best matches the truth's surface (`best_rotation`: ICP over both ways' nearest points from
  24 starts): orientation given without the point-to-point correspondence an own rig has
  (`bench/orientation.py`). The surfaces' best fit is not the silhouettes', so one fit can score
  lower turned than as fitted; over many fits it shows what the orientation is worth, and what
  is left beyond it is the template's shape and pose.

One JSON line a fit, then the means (BENCHMARKS.md, "What fixing the orientation could win at
most, for any template").
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import finish_lines, stored_bench_fits, stored_fits_parser  # noqa: E402

FLIPPED = 0.05  # a frame whose mirror scores this much higher counts as seen from the wrong side


def best_rotation(p: np.ndarray, g: np.ndarray, iterations: int = 30) -> np.ndarray:
    """(3, 3) the rotation R about ``p``'s centre that best lays points p (N, 3) on points g
    (M, 3), their centres put together: ICP over each side's nearest points on the other, from
    24 starts (the 24 turns that map the axes onto the axes), the least mean distance kept."""
    from itertools import permutations, product

    from scipy.spatial import cKDTree

    cp, cg = p.mean(0), g.mean(0)
    a0, b = p - cp, g - cg
    tree_g = cKDTree(b)
    best, best_cost = np.eye(3), np.inf
    for perm, signs in product(permutations(range(3)), product((1.0, -1.0), repeat=3)):
        R = np.eye(3)[list(perm)] * np.asarray(signs)[:, None]
        if np.linalg.det(R) < 0:
            continue
        for _ in range(iterations):
            q = a0 @ R.T
            _, j = tree_g.query(q)
            _, k = cKDTree(q).query(b)
            src, dst = np.concatenate([a0, a0[k]]), np.concatenate([b[j], b])
            U, _, Vt = np.linalg.svd(dst.T @ src)
            R = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt
        q = a0 @ R.T
        cost = tree_g.query(q)[0].mean() + cKDTree(q).query(b)[0].mean()
        if cost < best_cost:
            best, best_cost = R, cost
    return best


def depth_mirror_points(points: np.ndarray) -> np.ndarray:
    """(N, 3) camera-frame ``points`` mirrored in depth through their centre's depth, each moved
    along its ray so its projection is unchanged (module docstring)."""
    z = points[:, 2]
    zc = 0.5 * (z.max() + z.min())
    z2 = 2.0 * zc - z
    ratio = z2 / np.where(np.abs(z) > 1e-9, z, 1e-9)
    return np.stack([points[:, 0] * ratio, points[:, 1] * ratio, z2], axis=1)


def _per_frame(seen: list) -> np.ndarray:
    """(S,) each frame's IoU, the mean over the held-out cameras of `held_out_silhouettes`."""
    from zooctl.geometry import silhouette_iou

    return np.nanmean(np.stack([silhouette_iou(f, g) for _, f, g in seen]), axis=0)


def main() -> None:
    ap = stored_fits_parser(__doc__)
    ap.add_argument("--frames", type=int, default=4, help="frames scored a fit (the benchmark's 4)")
    args = ap.parse_args()

    from zooctl.fit import metrics

    lines, rows = [], []
    for name, rec, res in stored_bench_fits(args.store, args.fits, need="view_masks"):
        video = res.video
        scores = metrics.evaluate_fit(res, frames=args.frames, reanimate_iters=1)
        sel = np.asarray(scores["frames_evaluated"])
        pred, _ = metrics._camera_frame_pred(res, sel)
        scales, mirrored, turned = [], [], []
        for i, t in enumerate(sel):
            gt = metrics._camera_frame_gt(res, int(t))[0]
            # the frame's scale as the metric finds it, so the mirror is placed where the fit is
            scale = metrics.scale_line_search(
                metrics.surface_samples(pred[i], res.template.faces),
                metrics.surface_samples(gt, video.gt["faces"]),
            )[0]
            body = pred[i] * scale
            samples = metrics.surface_samples(body, res.template.faces, 1500)
            truth = metrics.surface_samples(gt, video.gt["faces"], 1500)
            centre = samples.mean(0)  # turned where it stands: its place is not at issue here
            scales.append(scale)
            mirrored.append(depth_mirror_points(body) / scale)
            turned.append(((body - centre) @ best_rotation(samples, truth).T + centre) / scale)
        scales, mirrored = np.array(scales), np.stack(mirrored)

        fitted, flipped, rotated = (
            _per_frame(metrics.held_out_silhouettes(res, sel, v, scales))
            for v in (pred, mirrored, np.stack(turned))
        )
        row = {
            "fit": name,
            "template": rec["template"],
            "novel": scores["novel_view_iou"],
            "novel_frames": [round(float(x), 3) for x in fitted],
            "novel_mirrored": float(np.nanmean(flipped)),
            "mirrored_frames": [round(float(x), 3) for x in flipped],
            "novel_better": float(np.nanmean(np.fmax(fitted, flipped))),
            "flipped_frames": int(np.sum(flipped > fitted + FLIPPED)),
            "novel_rotated": float(np.nanmean(rotated)),
            "rotated_frames": [round(float(x), 3) for x in rotated],
            "frames": [int(t) for t in sel],
        }
        rows.append(row)
        lines.append(json.dumps(row))
        print(lines[-1], flush=True)
    if not rows:
        sys.exit(f"error: no finished benchmark fits with held-out views in {args.store}")
    summary = {
        "fits": len(rows),
        "novel": float(np.mean([r["novel"] for r in rows])),
        "novel_mirrored": float(np.mean([r["novel_mirrored"] for r in rows])),
        "novel_better": float(np.mean([r["novel_better"] for r in rows])),
        "novel_rotated": float(np.mean([r["novel_rotated"] for r in rows])),
        "flipped_frames": int(sum(r["flipped_frames"] for r in rows)),
        "frames": int(sum(len(r["frames"]) for r in rows)),
        "fits_with_a_flipped_frame": int(sum(r["flipped_frames"] > 0 for r in rows)),
    }
    finish_lines(lines, summary, args.json)


if __name__ == "__main__":
    main()
