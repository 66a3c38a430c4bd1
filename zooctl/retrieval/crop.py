"""Square crops centred on the animal, made the same way for query frames and rendered views.

Both sides of retrieval see the animal at the same scale and position, so embeddings compare
shape and appearance rather than framing. The classifier of the semantic term gets ``inside``
crops instead: the square moved (and shrunk when it must) to lie within the frame, so it sees a
photograph rather than the smeared border pixels a crop past the frame's edge repeats.
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
    image: np.ndarray, mask: np.ndarray, size: int, margin: float = DEFAULT_MARGIN, inside: bool = False
) -> tuple[np.ndarray, np.ndarray] | None:
    """Crop image (H, W, 3) uint8 and mask (H, W) bool to a square around the mask, resized.

    Returns (size, size, 3) uint8 and (size, size) bool, or None when the mask is empty. Outside
    the frame the image's border pixels are repeated and the mask is empty. ``inside``: the square
    is moved, and shrunk to the frame's shorter side when it is larger, to lie within the frame
    (the same crop when it does already).
    """
    import cv2

    box = mask_box(mask)
    if box is None:
        return None
    x0, y0, x1, y1 = box
    side = max(x1 - x0, y1 - y0) * (1 + 2 * margin)
    if inside:
        x0, y0, x1, y1, side = _inside(box, side, mask.shape)
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


def _inside(
    box: tuple[float, float, float, float], side: float, shape: tuple[int, ...]
) -> tuple[float, float, float, float, float]:
    """A box with the same centre as ``box`` but moved so that a square of ``side`` (capped at the
    frame's shorter side) centred on it lies within a frame of ``shape``; and that side."""
    h, w = shape[:2]
    x0, y0, x1, y1 = box
    side = min(side, float(h), float(w))
    cx = min(max((x0 + x1) / 2, side / 2), w - side / 2)
    cy = min(max((y0 + y1) / 2, side / 2), h - side / 2)
    dx, dy = cx - (x0 + x1) / 2, cy - (y0 + y1) / 2
    return x0 + dx, y0 + dy, x1 + dx, y1 + dy, side
