"""Small numpy transform helpers shared by importers, exporters and the posing code.

Conventions used everywhere in zooctl:

- Quaternions are (w, x, y, z), unit length, Hamilton product.
- 4x4 matrices act on column vectors: ``p' = M @ [p, 1]``; translation in ``M[:3, 3]``.
- A local transform is ``T @ R @ S`` (glTF and USD order).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np


def quat_normalize(q: np.ndarray) -> np.ndarray:
    """(..., 4) -> (..., 4) unit quaternions; a zero quaternion becomes the identity."""
    q = np.asarray(q, dtype=np.float64)
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    ident = np.zeros_like(q)
    ident[..., 0] = 1.0
    return np.where(n > 1e-12, q / np.maximum(n, 1e-12), ident)


def hamilton(a: Sequence[Any], b: Sequence[Any]) -> tuple[Any, Any, Any, Any]:
    """The w, x, y, z components of the Hamilton product a * b, from the components of a and b
    (numpy arrays or torch tensors alike: only products and sums)."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (..., 4) wxyz quaternions (broadcasting)."""
    return np.stack(hamilton(np.moveaxis(np.asarray(a), -1, 0), np.moveaxis(np.asarray(b), -1, 0)), -1)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """(..., 4) wxyz -> (..., 3, 3) rotation matrices."""
    q = quat_normalize(q)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    m = np.empty(q.shape[:-1] + (3, 3), dtype=np.float64)
    m[..., 0, 0] = 1 - 2 * (y * y + z * z)
    m[..., 0, 1] = 2 * (x * y - w * z)
    m[..., 0, 2] = 2 * (x * z + w * y)
    m[..., 1, 0] = 2 * (x * y + w * z)
    m[..., 1, 1] = 1 - 2 * (x * x + z * z)
    m[..., 1, 2] = 2 * (y * z - w * x)
    m[..., 2, 0] = 2 * (x * z - w * y)
    m[..., 2, 1] = 2 * (y * z + w * x)
    m[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return m


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices -> (..., 4) wxyz with w >= 0 (Shepperd's method, vectorised)."""
    m = np.asarray(m, dtype=np.float64)
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    # Four candidate quaternions, each accurate where its pivot is large; keep the best one.
    piv = np.stack([1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22], -1)
    cand = np.stack(
        [
            np.stack(
                [
                    piv[..., 0],
                    m[..., 2, 1] - m[..., 1, 2],
                    m[..., 0, 2] - m[..., 2, 0],
                    m[..., 1, 0] - m[..., 0, 1],
                ],
                -1,
            ),
            np.stack(
                [
                    m[..., 2, 1] - m[..., 1, 2],
                    piv[..., 1],
                    m[..., 0, 1] + m[..., 1, 0],
                    m[..., 0, 2] + m[..., 2, 0],
                ],
                -1,
            ),
            np.stack(
                [
                    m[..., 0, 2] - m[..., 2, 0],
                    m[..., 0, 1] + m[..., 1, 0],
                    piv[..., 2],
                    m[..., 1, 2] + m[..., 2, 1],
                ],
                -1,
            ),
            np.stack(
                [
                    m[..., 1, 0] - m[..., 0, 1],
                    m[..., 0, 2] + m[..., 2, 0],
                    m[..., 1, 2] + m[..., 2, 1],
                    piv[..., 3],
                ],
                -1,
            ),
        ],
        -2,
    )
    k = np.argmax(piv, axis=-1)
    q = np.take_along_axis(cand, k[..., None, None], axis=-2)[..., 0, :]
    q = q / (2.0 * np.sqrt(np.maximum(np.take_along_axis(piv, k[..., None], -1), 1e-300)))
    q = np.where(q[..., :1] < 0, -q, q)
    return quat_normalize(q)


def quat_slerp(q0: np.ndarray, q1: np.ndarray, t: np.ndarray | float) -> np.ndarray:
    """Spherical interpolation, shortest path. q0, q1: (..., 4); t broadcast to (...)."""
    q0 = quat_normalize(q0)
    q1 = quat_normalize(q1)
    t = np.asarray(t, dtype=np.float64)[..., None]
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin = np.sin(theta)
    small = sin < 1e-6
    w0 = np.where(small, 1 - t, np.sin((1 - t) * theta) / np.where(small, 1, sin))
    w1 = np.where(small, t, np.sin(t * theta) / np.where(small, 1, sin))
    return quat_normalize(w0 * q0 + w1 * q1)


def rotation_angle_deg(R: np.ndarray) -> float:
    """The angle in degrees of the (3, 3) rotation ``R`` (how far it turns, about any axis)."""
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))))


def compose_trs(t: np.ndarray, q: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Translation (..., 3), rotation wxyz (..., 4), scale (..., 3) -> (..., 4, 4) = T @ R @ S."""
    t = np.asarray(t, dtype=np.float64)
    s = np.asarray(s, dtype=np.float64)
    r = quat_to_matrix(q)
    m = np.zeros(r.shape[:-2] + (4, 4))
    m[..., :3, :3] = r * s[..., None, :]
    m[..., :3, 3] = t
    m[..., 3, 3] = 1.0
    return m


def decompose_trs(m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(..., 4, 4) affine without shear -> translation (..., 3), wxyz (..., 4), scale (..., 3).

    A negative determinant is put into the x scale so the rotation stays proper.
    """
    m = np.asarray(m, dtype=np.float64)
    t = m[..., :3, 3].copy()
    a = m[..., :3, :3]
    s = np.linalg.norm(a, axis=-2)
    det = np.linalg.det(a)
    s[..., 0] = np.where(det < 0, -s[..., 0], s[..., 0])
    r = a / np.where(np.abs(s) > 1e-12, s, 1.0)[..., None, :]
    return t, matrix_to_quat(r), s


def global_transforms(local: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """Forward kinematics. local: (..., J, 4, 4), parents: (J,) with parents[j] < j or -1.

    Returns (..., J, 4, 4) joint-to-model transforms.
    """
    out = np.empty_like(local, dtype=np.float64)
    for j, p in enumerate(parents):
        out[..., j, :, :] = local[..., j, :, :] if p < 0 else out[..., p, :, :] @ local[..., j, :, :]
    return out


def silhouette_iou(sil: np.ndarray, masks: np.ndarray) -> np.ndarray:
    """(B,) IoU of bool silhouettes (B, H, W) with bool masks (B, H, W); NaN where a mask is empty."""
    B = len(masks)
    inter = (sil & masks).reshape(B, -1).sum(1)
    union = (sil | masks).reshape(B, -1).sum(1)
    return np.where(masks.reshape(B, -1).any(1), inter / np.maximum(union, 1), np.nan)


MASK_CHUNK = 64  # masks per read where every mask is needed: 26 MB at 854x480


def mask_chunks(masks: Any, size: int = MASK_CHUNK) -> Iterator[np.ndarray]:
    """Consecutive (n, H, W) bool blocks of (T, H, W) masks, an array or a stored video's
    `FrameArray` (read a block at a time): anything with ``len`` and frame slices."""
    for s in range(0, len(masks), size):
        yield np.asarray(masks[s : min(s + size, len(masks))], dtype=bool)


def nonempty_frames(masks: Any) -> np.ndarray:
    """(K,) int64 indices of the frames whose mask has a pixel set."""
    found = [np.zeros(0, np.int64)]
    for s, b in zip(range(0, len(masks), MASK_CHUNK), mask_chunks(masks), strict=True):
        found.append(s + np.flatnonzero(b.reshape(len(b), -1).any(1)))
    return np.concatenate(found)
