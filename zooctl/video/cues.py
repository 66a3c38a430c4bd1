"""Per-pixel foreground cues the classical segmenter fuses: colour, motion, and mask clean-up.

All maps are (H, W) float32 in [0, 1] ("how likely is this pixel the animal") unless stated.
"""

from __future__ import annotations

import cv2
import numpy as np

HIST_BINS = 16  # per Lab channel: 4096 bins, fine enough to split a black swan from grey concrete


def lab_bins(frame_rgb: np.ndarray, bins: int = HIST_BINS) -> np.ndarray:
    """(H, W, 3) uint8 RGB -> (H, W) int32 index of each pixel's quantised Lab colour."""
    lab = cv2.cvtColor(np.ascontiguousarray(frame_rgb), cv2.COLOR_RGB2LAB).astype(np.int32) * bins // 256
    return (lab[..., 0] * bins + lab[..., 1]) * bins + lab[..., 2]


def colour_histogram(bins_img: np.ndarray, region: np.ndarray, bins: int = HIST_BINS) -> np.ndarray:
    """Normalised (bins^3,) float64 histogram of the pixels in ``region`` (H, W) bool, Laplace-smoothed."""
    h = np.bincount(bins_img[region], minlength=bins**3).astype(np.float64) + 1.0
    return h / h.sum()


def colour_probability(bins_img: np.ndarray, hist_fg: np.ndarray, hist_bg: np.ndarray) -> np.ndarray:
    """Posterior P(fg | colour) with equal priors, per pixel."""
    ratio = hist_fg / (hist_fg + hist_bg)
    return ratio[bins_img].astype(np.float32)


def background_motion_residual(flow: np.ndarray, step: int = 8) -> np.ndarray:
    """(H, W, 2) flow -> (H, W) float32 pixels of motion not explained by the camera.

    The camera's motion is a homography fitted by RANSAC to a grid of flow samples (the background
    dominates most frames); what it leaves over is the animal's own motion (plus water, leaves).
    """
    h, w = flow.shape[:2]
    gy, gx = np.mgrid[0:h:step, 0:w:step]
    src = np.stack([gx.ravel(), gy.ravel()], 1).astype(np.float32)
    dst = src + flow[gy.ravel(), gx.ravel()]
    hom, _ = cv2.findHomography(src, dst, cv2.RANSAC, 1.0)
    if hom is None:  # degenerate (e.g. a flat frame): fall back to the median translation
        return np.linalg.norm(flow - np.median(flow.reshape(-1, 2), 0), axis=-1).astype(np.float32)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    pts = np.stack([xx, yy, np.ones_like(xx)], -1) @ hom.T.astype(np.float32)
    pred = pts[..., :2] / np.where(np.abs(pts[..., 2:]) < 1e-6, 1e-6, pts[..., 2:]) - np.stack([xx, yy], -1)
    return np.linalg.norm(flow - pred, axis=-1).astype(np.float32)


def motion_probability(residual: np.ndarray, region: np.ndarray, min_threshold: float = 0.5) -> np.ndarray:
    """Soft threshold of ``residual`` at Otsu's split of its values inside ``region`` (H, W) bool."""
    scale = 20.0  # Otsu works on uint8: 1/20 px resolution up to 12.75 px
    vals = np.clip(residual[region] * scale, 0, 255).astype(np.uint8)
    if vals.size < 16:
        return np.zeros_like(residual)
    th, _ = cv2.threshold(vals.reshape(-1, 1), 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    th = max(th / scale, min_threshold)
    return (1.0 / (1.0 + np.exp(-(residual - th) / (0.25 * th)))).astype(np.float32)


def largest_components(
    mask: np.ndarray, keep_ratio: float = 0.2, reference: np.ndarray | None = None
) -> np.ndarray:
    """Keep the largest 8-connected component and any at least ``keep_ratio`` of its size.

    With ``reference`` (H, W) bool, components are ranked by their overlap with it instead, so a
    leg cut off by a fence stays while a same-coloured bush across the frame goes.
    """
    n, lab, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    if n <= 2:
        return mask.astype(bool)
    score = stats[1:, cv2.CC_STAT_AREA].astype(np.float64)
    if reference is not None and reference.any():
        overlap = np.bincount(lab[reference], minlength=n)[1:].astype(np.float64)
        if overlap.max() > 0:
            score = overlap
    keep = np.zeros(n, bool)
    keep[1:] = score >= keep_ratio * score.max()
    keep[1 + int(np.argmax(score))] = True
    return keep[lab]


def fill_holes(mask: np.ndarray, max_fraction: float = 0.02) -> np.ndarray:
    """Fill enclosed background holes smaller than ``max_fraction`` of the frame (GrabCut speckle)."""
    inv = (~mask).astype(np.uint8)
    n, lab, stats, _ = cv2.connectedComponentsWithStats(inv, connectivity=4)
    if n <= 2:
        return mask.copy()
    h, w = mask.shape
    border = np.unique(np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]]))
    small = stats[:, cv2.CC_STAT_AREA] < max_fraction * h * w
    small[border] = False
    small[0] = False
    return mask | small[lab]


def box_of(mask: np.ndarray) -> tuple[int, int, int, int] | None:
    """(x, y, w, h) bounding box of a (H, W) bool mask, or None when it is empty."""
    ys, xs = np.nonzero(mask)
    if xs.size == 0:
        return None
    return int(xs.min()), int(ys.min()), int(xs.max() - xs.min() + 1), int(ys.max() - ys.min() + 1)


def box_mask(shape: tuple[int, int], box: tuple[int, int, int, int]) -> np.ndarray:
    m = np.zeros(shape, bool)
    x, y, w, h = box
    m[max(y, 0) : max(y + h, 0), max(x, 0) : max(x + w, 0)] = True
    return m


def disk(radius: int) -> np.ndarray:
    r = max(int(radius), 1)
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
