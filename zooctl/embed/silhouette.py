"""The ``silhouette`` embedder: a shape descriptor of the animal's mask, blind to texture.

The mask (already cropped to a square around the animal, see `zooctl.retrieval.crop`) is
area-resampled to a ``grid x grid`` occupancy map, blurred so that a slightly shifted or thinner
leg still overlaps, mapped to [-1, 1] (background -1, so that shared *empty* space counts as
agreement too) and made zero-mean and unit-length. The cosine of two such vectors falls linearly
with the area where the masks disagree, i.e. it behaves like an IoU that tolerates small shifts.
"""

from __future__ import annotations

import numpy as np

from .base import check_masks, l2_normalize

DEFAULT_GRID = 24


class SilhouetteEmbedder:
    """Mask -> (grid * grid,) descriptor. See the module docstring."""

    name = "silhouette"
    input_kind = "mask"

    def __init__(self, device: str = "cpu", grid: int = DEFAULT_GRID, blur: float = 0.8):
        if grid < 4:
            from ..errors import UsageError

            raise UsageError(f"silhouette grid {grid} is too small", hint="use at least 4 (default 24)")
        self.grid = int(grid)
        self.blur = float(blur)
        self.dim = self.grid * self.grid
        self.identity = f"silhouette/{self.grid}/{self.blur:g}"

    def embed_batch(self, masks: np.ndarray) -> np.ndarray:
        """(N, H, W) bool -> (N, grid*grid) float32 unit-norm descriptors."""
        import cv2

        masks = check_masks(masks)
        g = self.grid
        out = np.empty((len(masks), g * g), dtype=np.float32)
        for i, m in enumerate(masks):
            occ = cv2.resize(m.astype(np.float32), (g, g), interpolation=cv2.INTER_AREA)
            if self.blur > 0:
                occ = cv2.GaussianBlur(occ, (0, 0), self.blur)
            v = 2.0 * occ.reshape(-1) - 1.0
            out[i] = v - v.mean()
        return l2_normalize(out)
