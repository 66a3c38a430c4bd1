"""A user's box as a hint: which animal, carried through the video along the flow.

The box says which animal the user means on one frame. `carry` moves that choice to every other
frame along the flow, so the localiser can seed where it sees the animal best (not only on the
box's frame) while it keeps to the animal the box chose; `agrees` checks the result against the box.
"""

from __future__ import annotations

import cv2
import numpy as np

from . import cues
from .flow import warp


def carry(region: np.ndarray, forward, backward, frame: int, out=None) -> np.ndarray:
    """(H, W) bool region on frame ``frame`` -> (T, H, W) bool: where it is on every frame.

    ``forward`` / ``backward``: (T-1, H, W, 2) flow from frame i to i+1 and from i+1 to i. The region
    is warped frame by frame as a soft map (what drifts off the animal fades instead of cutting it),
    and kept where it holds at least a quarter of its weight, widened by a band of a tenth of its size
    so the animal's own evidence, not the warp's outline, decides where it ends. ``out``: a zeroed
    (T, H, W) bool array-like to fill (a scratch array for a long video) instead of a new array.
    """
    t = len(forward) + 1
    out = np.zeros((t, *region.shape), bool) if out is None else out
    out[frame] = region
    for order, pulls in ((range(frame + 1, t), backward), (range(frame - 1, -1, -1), forward)):
        soft = region.astype(np.float32)  # one frame at a time: long videos hold only the bool maps
        for i in order:
            soft = warp(soft, pulls[i - 1] if i > frame else pulls[i])
            out[i] = soft >= 0.25
    for i in range(t):
        m = out[i]
        if m.any():
            r = 0.1 * float(np.sqrt(m.sum()))
            out[i] = cv2.dilate(m.astype(np.uint8), cues.disk(r)).astype(bool)
    return out


def agrees(mask: np.ndarray, box: tuple[int, int, int, int], margin: float = 0.1) -> bool:
    """Whether a (H, W) bool mask is the animal a box (x, y, w, h) was drawn around: most of it lies
    in the box (widened by ``margin`` of its longer side: hand-drawn boxes cut off paws and ears)
    and its own box fills a fair part of the user's."""
    got = cues.box_of(mask)
    if got is None:
        return False
    x, y, w, h = box
    m = round(margin * max(w, h))
    inside = (mask & cues.box_mask(mask.shape, (x - m, y - m, w + 2 * m, h + 2 * m))).sum()
    gx, gy, gw, gh = got
    ix = max(0, min(gx + gw, x + w) - max(gx, x))
    iy = max(0, min(gy + gh, y + h) - max(gy, y))
    return bool(inside >= 0.8 * mask.sum() and ix * iy >= 0.3 * w * h)


def touching(parts: np.ndarray, region: np.ndarray) -> np.ndarray:
    """(H, W) bool: the 8-connected parts of ``parts`` that overlap ``region`` (both (H, W) bool),
    whole: the region picks an object without cutting it to its own outline."""
    n, lab = cv2.connectedComponents(parts.astype(np.uint8), connectivity=8)
    hit = np.zeros(n, bool)
    hit[np.unique(lab[region & parts])] = True
    hit[0] = False
    return hit[lab]


def focus(score: np.ndarray, region: np.ndarray, floor: float = 0.25) -> np.ndarray:
    """A fused localiser map (H, W) float32 in [0, 1] seen from a region (H, W) bool: the evidence
    rescaled to its peak in the region (a second, smaller animal has weaker evidence than the
    frame's main one) and kept only where it connects to the region; zero when the region's peak is
    under ``floor`` (nothing there stands out as an animal)."""
    peak = float((score * region).max())
    if peak < floor:
        return np.zeros_like(score)
    score = np.clip(score / peak, 0.0, 1.0)
    return score * touching(score > 0.4, region)
