"""Closed tube meshes swept along centre lines: every body part of a procedural animal is one.

A part is a centre line (N, 3) with an elliptical cross-section (side and up radii per point) and
a cap vertex at each end, so each part is a closed, consistently oriented (outward) surface. Parts
overlap where they attach (a leg starts inside the body), which reads as one animal.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Part:
    """One body part.

    centerline: (N, 3) points in bind space; radii: (N, 2) (side, up) cross-section radii;
    up: (3,) direction the "up" radius points to (roughly perpendicular to the centre line);
    chain: joints whose bones run along the part, first to last; anchor: the joint the part hangs
    from (it shares the weights at the attachment); color: (3,) linear RGB, belly: colour of the
    underside (None: same as color).
    """

    name: str
    centerline: np.ndarray
    radii: np.ndarray
    up: np.ndarray
    chain: list[str]
    anchor: str | None = None
    color: np.ndarray = field(default_factory=lambda: np.array([0.6, 0.5, 0.4]))
    belly: np.ndarray | None = None
    segments: int = 16


def polyline(points: list[np.ndarray] | np.ndarray, n: int) -> np.ndarray:
    """Resample the polyline through ``points`` (M, 3) to ``n`` points evenly spaced by arc length."""
    pts = np.asarray(points, dtype=np.float64)
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    t = np.linspace(0.0, s[-1], n)
    return np.stack([np.interp(t, s, pts[:, k]) for k in range(3)], axis=1)


def tube(part: Part) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sweep ``part`` into a closed mesh.

    Returns vertices (N*S + 2, 3), faces (F, 3) int32 (outward, counter-clockwise seen from
    outside), centre-line index of each vertex (N*S + 2,) (the caps take the end indices) and the
    "underside" amount of each vertex in [0, 1] (for belly colouring).
    """
    c = np.asarray(part.centerline, dtype=np.float64)
    r = np.asarray(part.radii, dtype=np.float64)
    n, segs = len(c), part.segments
    tang = np.gradient(c, axis=0)
    tang /= np.linalg.norm(tang, axis=1, keepdims=True).clip(1e-12)
    # Parallel-transport a side vector along the line so the rings never twist.
    side = np.empty_like(c)
    ref = np.asarray(part.up, dtype=np.float64)
    s0 = np.cross(ref, tang[0])
    if np.linalg.norm(s0) < 1e-6:
        s0 = np.cross([1.0, 0.0, 0.0], tang[0])
    side[0] = s0 / np.linalg.norm(s0)
    for i in range(1, n):
        s = side[i - 1] - np.dot(side[i - 1], tang[i]) * tang[i]
        side[i] = s / max(np.linalg.norm(s), 1e-12)
    upv = np.cross(tang, side)
    theta = np.linspace(0.0, 2 * np.pi, segs, endpoint=False)
    cos, sin = np.cos(theta), np.sin(theta)
    # Keep the smallest ring slightly open so that the caps are never degenerate.
    rr = np.maximum(r, 1e-3 * max(float(r.max()), 1e-6))
    ring = (
        c[:, None, :]
        + side[:, None, :] * (rr[:, 0, None, None] * cos[None, :, None])
        + upv[:, None, :] * (rr[:, 1, None, None] * sin[None, :, None])
    )
    cap0 = c[0] - tang[0] * 0.35 * rr[0].mean()
    cap1 = c[-1] + tang[-1] * 0.35 * rr[-1].mean()
    verts = np.concatenate([ring.reshape(-1, 3), cap0[None], cap1[None]])

    idx = np.arange(n * segs).reshape(n, segs)
    a, b = idx[:-1], idx[1:]
    a1, b1 = np.roll(a, -1, axis=1), np.roll(b, -1, axis=1)
    side_faces = np.concatenate(
        [np.stack([a, a1, b], -1).reshape(-1, 3), np.stack([a1, b1, b], -1).reshape(-1, 3)]
    )
    i0, i1 = n * segs, n * segs + 1
    j = np.arange(segs)
    jn = np.roll(j, -1)
    start = np.stack([np.full(segs, i0), idx[0, jn], idx[0, j]], -1)
    end = np.stack([np.full(segs, i1), idx[-1, j], idx[-1, jn]], -1)
    faces = np.concatenate([side_faces, start, end]).astype(np.int32)

    line_index = np.concatenate([np.repeat(np.arange(n), segs), [0, n - 1]])
    # How much a ring vertex faces world-down: the underside gets the belly colour.
    normal_dir = side[:, None, :] * cos[None, :, None] + upv[:, None, :] * sin[None, :, None]
    under = np.clip(-normal_dir[..., 1], 0.0, 1.0).reshape(-1)
    under = np.concatenate([under, [0.0, 0.0]])
    return verts, faces, line_index, under
