"""Square crops centred on the animal, made the same way for query frames and rendered views.

Both sides of retrieval see the animal at the same scale and position, so embeddings compare
shape and appearance rather than framing.
"""

from __future__ import annotations

import numpy as np

DEFAULT_MARGIN = 0.08  # of the box side, on each side


def mask_box(mask: np.ndarray) -> tuple[float, float, float, float] | None:
    """(x0, y0, x1, y1) pixel-edge bounds of a (H, W) mask's true pixels, or None when empty."""
    rows = np.flatnonzero(mask.any(1))
    if len(rows) == 0:
        return None
    cols = np.flatnonzero(mask.any(0))
    return float(cols[0]), float(rows[0]), float(cols[-1] + 1), float(rows[-1] + 1)


def square_crop(
    image: np.ndarray, mask: np.ndarray, size: int, margin: float = DEFAULT_MARGIN
) -> tuple[np.ndarray, np.ndarray] | None:
    """Crop image (H, W, 3) uint8 and mask (H, W) bool to a square around the mask, resized.

    Returns (size, size, 3) uint8 and (size, size) bool, or None when the mask is empty. Outside
    the frame the image's border pixels are repeated and the mask is empty.
    """
    import cv2

    box = mask_box(mask)
    if box is None:
        return None
    x0, y0, x1, y1 = box
    side = max(x1 - x0, y1 - y0) * (1 + 2 * margin)
    s = size / side
    if s < 0.75:  # shrink the whole frame with area averaging first: warpAffine would alias
        h, w = mask.shape
        nw, nh = max(1, round(w * s)), max(1, round(h * s))
        image = cv2.resize(image, (nw, nh), interpolation=cv2.INTER_AREA)
        mask = cv2.resize(mask.astype(np.uint8) * 255, (nw, nh), interpolation=cv2.INTER_AREA) >= 128
        fx, fy = nw / w, nh / h
        x0, x1, y0, y1 = x0 * fx, x1 * fx, y0 * fy, y1 * fy
        side *= (fx + fy) / 2
        s = size / side
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    # Affine map from source pixels to crop pixels (pixel centres at +0.5 in both images).
    M = np.array([[s, 0, size / 2 - s * cx + 0.5 * s - 0.5], [0, s, size / 2 - s * cy + 0.5 * s - 0.5]])
    img = cv2.warpAffine(image, M, (size, size), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    m = (
        cv2.warpAffine(
            mask.astype(np.uint8) * 255,
            M,
            (size, size),
            flags=cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_CONSTANT,
        )
        >= 128
    )
    return img, m
