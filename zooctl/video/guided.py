"""Masks decided at a working size brought to the frame's size along the frame's own edges.

A mask decided on a coarse grid and upsampled linearly has a blurred, rounded outline: it cuts
across ears, paws and the gap between two legs wherever the grid's cells do. The guided filter (He,
Sun and Tang, "Guided Image Filtering", 2013; the fast variant of He and Sun, 2015) fits, in every
window, the mask as an affine function of the frame's colour, so the upsampled mask's outline
follows the colour edges of the full-size frame. The coefficients are fitted on the frame at the
working size (where the mask was decided) and applied to the full-size frame.
"""

from __future__ import annotations

import cv2
import numpy as np


def _solve3(var: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """(..., 3, 3) symmetric positive definite and (..., 3) -> (..., 3) var^-1 cov, by cofactors
    (one pass of array arithmetic rather than a LAPACK call per pixel)."""
    a, b, c = var[..., 0, 0], var[..., 0, 1], var[..., 0, 2]
    e, f, i = var[..., 1, 1], var[..., 1, 2], var[..., 2, 2]
    ca, cb, cc = e * i - f * f, c * f - b * i, b * f - c * e
    ce, cf, ci = a * i - c * c, b * c - a * f, a * e - b * b
    det = a * ca + b * cb + c * cc
    x0 = ca * cov[..., 0] + cb * cov[..., 1] + cc * cov[..., 2]
    x1 = cb * cov[..., 0] + ce * cov[..., 1] + cf * cov[..., 2]
    x2 = cc * cov[..., 0] + cf * cov[..., 1] + ci * cov[..., 2]
    return np.stack([x0, x1, x2], -1) / det[..., None]


def guided_coefficients(guide: np.ndarray, p: np.ndarray, radius: int, eps: float):
    """Colour guided filter's coefficients: (h, w, 3) float32 guide in [0, 1] and (h, w) float32
    input -> ((h, w, 3) A, (h, w) b), each the mean over the windows covering a pixel, so that
    A . guide + b is the filtered input (at any size the coefficients are resized to)."""
    k = (2 * radius + 1, 2 * radius + 1)

    def box(x):
        return cv2.boxFilter(x, -1, k)

    m_i, m_p = box(guide), box(p)
    cov = box(guide * p[..., None]) - m_i * m_p[..., None]
    var = np.empty((*p.shape, 3, 3), np.float32)
    for r in range(3):
        for c in range(r, 3):
            var[..., r, c] = var[..., c, r] = box(guide[..., r] * guide[..., c]) - m_i[..., r] * m_i[..., c]
    var += eps * np.eye(3, dtype=np.float32)
    a = _solve3(var, cov).astype(np.float32)
    b = m_p - (a * m_i).sum(-1)
    return box(a), box(b)


def guided_upsample(
    mask: np.ndarray, small: np.ndarray, frame: np.ndarray, radius: float = 0.02, eps: float = 1e-3
) -> np.ndarray:
    """(h, w) bool mask decided on (h, w, 3) uint8 ``small`` -> (H, W) bool on (H, W, 3) uint8
    ``frame`` (the same picture at its own size), its outline on the frame's colour edges.

    ``radius``: the filter's window, a fraction of the working frame's larger side (at least one
    pixel). ``eps``: the regulariser on the colour's variance (colours in [0, 1]): flat regions keep
    the mask's own values. An empty mask stays empty; a mask too thin for the window to keep is
    upsampled linearly instead (a frame with an animal keeps a mask)."""
    h, w = mask.shape
    H, W = frame.shape[:2]
    if not mask.any():
        return np.zeros((H, W), bool)
    r = max(int(round(radius * max(h, w))), 1)
    # the filter moves the outline at most two windows' radius: the rest of the frame is left out
    ys, xs = np.nonzero(mask)
    margin = 2 * r + 2
    y0, y1 = max(int(ys.min()) - margin, 0), min(int(ys.max()) + margin + 1, h)
    x0, x1 = max(int(xs.min()) - margin, 0), min(int(xs.max()) + margin + 1, w)
    guide = small[y0:y1, x0:x1].astype(np.float32) * np.float32(1 / 255)
    a_crop, b_crop = guided_coefficients(guide, mask[y0:y1, x0:x1].astype(np.float32), r, eps)
    a, b = np.zeros((h, w, 3), np.float32), np.zeros((h, w), np.float32)
    a[y0:y1, x0:x1], b[y0:y1, x0:x1] = a_crop, b_crop
    if (H, W) != (h, w):
        a = cv2.resize(a, (W, H), interpolation=cv2.INTER_LINEAR)
        b = cv2.resize(b, (W, H), interpolation=cv2.INTER_LINEAR)
    Y0, Y1 = y0 * H // h, min(-(-y1 * H // h), H)
    X0, X1 = x0 * W // w, min(-(-x1 * W // w), W)
    full = frame[Y0:Y1, X0:X1].astype(np.float32) * np.float32(1 / 255)
    out = np.zeros((H, W), bool)
    out[Y0:Y1, X0:X1] = (a[Y0:Y1, X0:X1] * full).sum(-1) + b[Y0:Y1, X0:X1] > 0.5
    if not out.any():
        return cv2.resize(mask.astype(np.float32), (W, H), interpolation=cv2.INTER_LINEAR) > 0.5
    return out
