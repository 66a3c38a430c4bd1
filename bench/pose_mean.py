"""What a fit's per-frame joint rotations are worth in its novel view: each stored benchmark fit
scored as fitted, then with every frame's joints pulled towards the clip's mean pose.

    python bench/pose_mean.py --store STORE [FIT ...] [--json OUT]

For fits of `zooctl bench run` in STORE (default: every finished fit there), reloaded from their
``state.pt`` (no iteration runs). The root's rotation and translation, the shape and the camera
stay as fitted; only the joints' rotations change:

- ``fitted``: as fitted;
- ``half``: each frame's rotation half-way to the clip's mean (the normalised sum of the two
  quaternions, signs aligned);
- ``mean``: every frame at the clip's mean rotation per joint (the normalised mean quaternion):
  the fitted character as a statue of its average pose, carried along the fitted root;
- ``rest``: every frame at the template's rest pose.

The novel-view IoU is `zooctl bench run`'s (`zooctl.fit.metrics.evaluate_fit`, its 4 frames). A
fit whose ``mean`` beats ``fitted`` would be better off without its per-frame poses: a sign the
poses bend a wrong template into the silhouettes rather than follow the animal (BENCHMARKS.md,
"What the fit's poses are worth").
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import finish_lines, stored_bench_fits, stored_fits_parser  # noqa: E402

VARIANTS = ("fitted", "half", "mean", "rest")


def pose_variants(q, rest) -> dict:
    """(T, J, 4) quaternions ``q`` and the (J, 4) ``rest`` -> each variant's (T, J, 4) (docstring)."""
    aligned = q * np.sign((q * q[:1]).sum(-1, keepdims=True) + 1e-12)
    mean = aligned.mean(0)
    mean = mean / np.linalg.norm(mean, axis=-1, keepdims=True)
    half = aligned + mean[None]
    return {
        "fitted": q,
        "half": half / np.linalg.norm(half, axis=-1, keepdims=True),
        "mean": np.broadcast_to(mean, q.shape),
        "rest": np.broadcast_to(rest, q.shape),
    }


def main() -> None:
    args = stored_fits_parser(__doc__).parse_args()

    import torch

    from zooctl.fit import metrics

    lines, rows = [], []
    for name, rec, res in stored_bench_fits(args.store, args.fits, need="view_masks"):
        rotations = res.scene.rotations
        q0 = rotations.detach().cpu().numpy().astype(np.float64)
        rest = res.scene.model.rest_rotation.detach().cpu().numpy().astype(np.float64)
        row = {"fit": name, "template": rec["template"]}
        for variant, q in pose_variants(q0, rest).items():
            with torch.no_grad():
                rotations.copy_(torch.as_tensor(np.ascontiguousarray(q), dtype=rotations.dtype))
            row[variant] = round(
                float(metrics.evaluate_fit(res, frames=4, reanimate_iters=1)["novel_view_iou"]), 4
            )
        rows.append(row)
        lines.append(json.dumps(row))
        print(lines[-1], flush=True)
    if not rows:
        sys.exit(f"error: no finished benchmark fits with held-out views in {args.store}")
    summary = {"fits": len(rows), **{v: round(float(np.mean([r[v] for r in rows])), 4) for v in VARIANTS}}
    summary["mean_over_fitted"] = int(sum(r["mean"] > r["fitted"] for r in rows))
    summary["half_over_fitted"] = int(sum(r["half"] > r["fitted"] for r in rows))
    finish_lines(lines, summary, args.json)


if __name__ == "__main__":
    main()
