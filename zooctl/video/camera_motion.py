"""The camera's turn between frames, read from how the background moves.

A distant background moves in the image by the camera's rotation alone: a point seen along the
unit ray ``b`` (camera axes) in one frame is seen along ``R b`` in the next, whatever the camera's
translation, for points far enough. So each pair of consecutive frames gives ``R`` from points
tracked outside the animal (Shi-Tomasi corners, pyramidal Lucas-Kanade, forwards and back),
by RANSAC over pairs of rays (two rays fix a rotation) with the inliers' least-squares rotation
(Kabsch) at the end. A pair with too few consistent points (a plain wall, a blurred pan, water)
gets no turn and is counted as unknown, which is what a fit assumed before: a camera at rest.

Near backgrounds and a camera that travels with the animal (parallax) bias the turn; the fit
uses it as a prediction for its tracker, which still checks every keyframe against the
silhouette (`zooctl.fit.camera_init`), never as a known camera.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..geometry import rotation_angle_deg

# Working size (longest side, pixels) and the tracker's settings.
_WORK_SIDE = 320
_MAX_CORNERS = 200
_CORNER_QUALITY = 0.003  # of the strongest corner: faint ground texture still gives points
_MIN_POINTS = 20  # consistent points a pair needs for its turn to count
_MIN_INLIER_SHARE = 0.5
_RANSAC_ROUNDS = 200
_INLIER_PX = 1.0  # at the working size
_BACK_PX = 0.5  # forward-backward disagreement at the working size
_MARGIN = 0.04  # of the longest side: mask dilation and image border kept clear


@dataclass
class CameraMotion:
    """``rotations`` (T, 3, 3) world-to-camera rotations, frame 0 the world (OpenCV axes: x right,
    y down, z forward); ``known`` (T-1,) bool: whether pair t -> t+1's turn was measured (else
    none was assumed); ``points`` (T-1,) the consistent background points of each pair."""

    rotations: np.ndarray
    known: np.ndarray
    points: np.ndarray

    def span_deg(self) -> float:
        """The largest turn of any frame from the first, in degrees."""
        return max((rotation_angle_deg(R) for R in self.rotations), default=0.0)

    def summary(self) -> dict[str, Any]:
        """What fit.json records: pairs measured, the median points, the turn over the video."""
        T = len(self.rotations)
        total = rotation_angle_deg(self.rotations[-1]) if T > 1 else 0.0
        path = sum(
            rotation_angle_deg(self.rotations[t + 1] @ self.rotations[t].T)
            for t in range(T - 1)
            if self.known[t]
        )
        return {
            "span_deg": round(self.span_deg(), 1),
            "pairs": int(T - 1),
            "pairs_measured": int(self.known.sum()),
            "median_points": int(np.median(self.points)) if len(self.points) else 0,
            "turn_deg": round(float(path), 1),
            "net_turn_deg": round(float(total), 1),
        }


def kabsch(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(3, 3) the rotation R that best maps unit rays ``a`` (N, 3) onto ``b`` (N, 3) (``b ~ a @ R.T``),
    least squares."""
    H = a.T @ b
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(Vt.T @ U.T)) or 1.0
    return Vt.T @ np.diag([1.0, 1.0, d]) @ U.T


def rotation_ransac(
    a: np.ndarray, b: np.ndarray, threshold: float, rng: np.random.Generator, rounds: int = _RANSAC_ROUNDS
) -> tuple[np.ndarray, np.ndarray]:
    """(R (3, 3), inliers (N,) bool): the rotation taking rays ``a`` to ``b`` (N, 3 each, unit) that most
    pairs agree with to within ``threshold`` radians, refitted on them (all ``rounds`` hypotheses at once)."""
    N = len(a)
    if N < 2:
        return np.eye(3), np.zeros(N, bool)
    i = rng.integers(0, N, rounds)
    j = (i + rng.integers(1, N, rounds)) % N  # another point
    A, B = np.stack([a[i], a[j]], 1), np.stack([b[i], b[j]], 1)  # (r, 2, 3)
    U, _, Vt = np.linalg.svd(A.transpose(0, 2, 1) @ B)
    V, Ut = Vt.transpose(0, 2, 1), U.transpose(0, 2, 1)
    D = np.ones((rounds, 3))
    D[:, 2] = np.where(np.linalg.det(V @ Ut) < 0, -1.0, 1.0)
    R = (V * D[:, None, :]) @ Ut  # (r, 3, 3)
    counts = (np.linalg.norm(a[None] @ R.transpose(0, 2, 1) - b[None], axis=-1) < threshold).sum(1)
    best = np.linalg.norm(a @ R[int(np.argmax(counts))].T - b, axis=1) < threshold
    if best.sum() < 2:
        return np.eye(3), best
    R = kabsch(a[best], b[best])
    inl = np.linalg.norm(a @ R.T - b, axis=1) < threshold
    if inl.sum() >= 2:
        R = kabsch(a[inl], b[inl])
    return R, inl


def _rays(pts: np.ndarray, focal: float, principal: tuple[float, float]) -> np.ndarray:
    r = np.column_stack(
        [(pts[:, 0] - principal[0]) / focal, (pts[:, 1] - principal[1]) / focal, np.ones(len(pts))]
    )
    return r / np.linalg.norm(r, axis=1, keepdims=True)


def background_motion(
    frames: Iterable[np.ndarray],
    masks: Iterable[np.ndarray],
    focal: float,
    principal: tuple[float, float] | None = None,
    seed: int = 0,
) -> CameraMotion:
    """The camera's rotation at every frame from the background's motion (module docstring).

    frames: T images (H, W, 3) uint8 RGB, or (H, W) gray; masks: T (H, W) bool, the animal (kept
    clear, dilated); focal and ``principal`` (default the centre) in pixels of the frames.
    """
    import cv2

    rng = np.random.default_rng(seed)
    rots = [np.eye(3)]
    known: list[bool] = []
    counts: list[int] = []
    prev = None
    for frame, mask in zip(frames, masks, strict=True):
        img = np.asarray(frame)
        H, W = img.shape[:2]
        s = min(1.0, _WORK_SIDE / max(H, W))
        size = (max(int(round(W * s)), 8), max(int(round(H * s)), 8))
        gray = cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) if img.ndim == 3 else img
        gray = cv2.resize(gray, size, interpolation=cv2.INTER_AREA)
        m = cv2.resize(np.asarray(mask, np.uint8), size, interpolation=cv2.INTER_NEAREST)
        r = max(int(round(_MARGIN * max(size))), 1)
        m = cv2.dilate(m, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))) > 0
        clear = ~m
        clear[:r], clear[-r:], clear[:, :r], clear[:, -r:] = False, False, False, False
        if prev is not None:
            R, n = _pair_turn(prev[0], gray, prev[1], clear, focal * s, _principal(principal, W, H, s), rng)
            known.append(R is not None)
            counts.append(n)
            rots.append((R if R is not None else np.eye(3)) @ rots[-1])
        prev = (gray, clear)
    return CameraMotion(np.stack(rots), np.asarray(known, bool), np.asarray(counts, int))


def _principal(principal: tuple[float, float] | None, W: int, H: int, s: float) -> tuple[float, float]:
    cx, cy = principal if principal is not None else (W / 2.0, H / 2.0)
    return cx * s, cy * s


def _pair_turn(
    g0: np.ndarray,
    g1: np.ndarray,
    clear0: np.ndarray,
    clear1: np.ndarray,
    focal: float,
    principal: tuple[float, float],
    rng: np.random.Generator,
) -> tuple[np.ndarray | None, int]:
    """(R or None, consistent points) for one pair of working-size gray frames."""
    import cv2

    pts = cv2.goodFeaturesToTrack(g0, _MAX_CORNERS, _CORNER_QUALITY, 6, mask=clear0.astype(np.uint8))
    if pts is None or len(pts) < _MIN_POINTS:
        return None, 0
    lk = {"winSize": (21, 21), "maxLevel": 3}
    p1, st, _ = cv2.calcOpticalFlowPyrLK(g0, g1, pts, None, **lk)
    p0b, st_b, _ = cv2.calcOpticalFlowPyrLK(g1, g0, p1, None, **lk)
    p0, p1, p0b = pts[:, 0], p1[:, 0], p0b[:, 0]
    h, w = g1.shape
    inside = (p1[:, 0] >= 0) & (p1[:, 0] < w) & (p1[:, 1] >= 0) & (p1[:, 1] < h)
    ok = st[:, 0].astype(bool) & st_b[:, 0].astype(bool) & inside
    ok &= np.linalg.norm(p0 - p0b, axis=1) < _BACK_PX
    xi = np.clip(p1[:, 0].astype(int), 0, w - 1)
    yi = np.clip(p1[:, 1].astype(int), 0, h - 1)
    ok &= clear1[yi, xi]  # lands on background in the next frame too
    if ok.sum() < _MIN_POINTS:
        return None, int(ok.sum())
    a, b = (
        _rays(p0[ok].astype(np.float64), focal, principal),
        _rays(p1[ok].astype(np.float64), focal, principal),
    )
    R, inl = rotation_ransac(a, b, _INLIER_PX / focal, rng)
    n = int(inl.sum())
    if n < _MIN_POINTS or n < _MIN_INLIER_SHARE * len(a):
        return None, n
    return R, n
