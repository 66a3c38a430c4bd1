"""Numbers `video show` prints: per-frame mask coverage and boxes, flow magnitude statistics."""

from __future__ import annotations

from typing import Any

import numpy as np


def video_stats(rec) -> dict[str, Any]:
    """A `VideoRecord` with masks and flow -> JSON-ready statistics."""
    from ..store.videos import boxes_of

    t = len(rec.masks)
    coverage = rec.masks.reshape(t, -1).mean(1)
    mag = np.linalg.norm(rec.flow_forward, axis=-1)
    occ = np.concatenate([rec.occlusion_forward.reshape(-1), rec.occlusion_backward.reshape(-1)])
    return {
        "mask_coverage": [round(float(c), 5) for c in coverage],
        "boxes": boxes_of(rec.masks).tolist(),
        "flow": {
            "mean_magnitude": float(mag.mean()),
            "p99_magnitude": float(np.percentile(mag, 99)),
            "max_magnitude": float(mag.max()),
            "occluded_fraction": float(occ.mean()),
            "per_frame_mean_magnitude": [round(float(m), 4) for m in mag.reshape(t - 1, -1).mean(1)],
        },
    }
