"""Priors of CASA's articulation fit: motion smoothness (eq. 6), symmetry (eq. 7), bone lengths.

The symmetry plane is *found* from the template (`find_symmetry_plane`), never assumed to be x=0:
PCA gives three candidate planes through the centroid, the best by Chamfer distance is refined
by iterating "reflect, match nearest, re-fit the plane to the matched pairs".
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.spatial import cKDTree

from ..errors import InputError

Tensor = torch.Tensor


def smoothness_loss(rotations: Tensor) -> Tensor:
    """Eq. 6: ``q_k^t * inverse(q_k^{t+1})`` should be the identity.

    rotations (..., T, J, 4) unit quaternions. The scalar part w of the relative rotation is
    ``cos(angle / 2)`` up to the q/-q sign, so ``1 - w^2 = sin^2(angle / 2)`` is sign-invariant.
    Returns a scalar (mean over frames pairs and joints; 0 for fewer than two frames).
    """
    if rotations.shape[-3] < 2:
        return rotations.sum() * 0.0
    # the w of q_t * conj(q_t+1) is their dot product: the whole Hamilton product is not needed
    w = (rotations[..., :-1, :, :] * rotations[..., 1:, :, :]).sum(-1)
    return (1.0 - w**2).mean()


def reflect(points: Tensor, normal: Tensor, offset: Tensor | float) -> Tensor:
    """Reflect (..., N, 3) points through the plane ``normal . x = offset`` (unit normal).

    Householder: ``x' = (I - 2 n n^T) x + 2 offset n``.
    """
    dist = (points * normal).sum(-1, keepdim=True) - offset
    return points - 2.0 * dist * normal


def chamfer(a: Tensor, b: Tensor) -> Tensor:
    """Symmetric squared Chamfer distance between (..., N, 3) and (..., M, 3) (scalar, mean)."""
    d = torch.cdist(a, b) ** 2
    return d.min(-1).values.mean() + d.min(-2).values.mean()


def symmetry_loss(
    points: Tensor, normal: Tensor, offset: Tensor | float, sample: Tensor | None = None
) -> Tensor:
    """Eq. 7: Chamfer distance between canonical points (..., N, 3) and their reflection.

    ``sample`` (S,) optional point indices to bound the O(N^2) cost on big meshes.
    """
    if sample is not None:
        points = points.index_select(-2, torch.as_tensor(sample, device=points.device))
    return chamfer(points, reflect(points, normal, offset))


def bone_length_prior(log_scales: Tensor, pairs: Tensor | None = None) -> Tensor:
    """Keep bones near their template length, and left/right bones equally long.

    log_scales (..., J) log bone-length scales; pairs (P, 2) long symmetric joints (optional).
    Returns ``mean(log b^2) + mean((log b_l - log b_r)^2)``.
    """
    loss = (log_scales**2).mean()
    if pairs is not None and len(pairs):
        left, right = log_scales.index_select(-1, pairs[:, 0]), log_scales.index_select(-1, pairs[:, 1])
        loss = loss + ((left - right) ** 2).mean()
    return loss


def _one_way(tree: cKDTree, pts: np.ndarray, normal: np.ndarray, offset: float) -> float:
    refl = pts - 2.0 * ((pts @ normal) - offset)[:, None] * normal
    return float(np.mean(tree.query(refl)[0] ** 2))


def find_symmetry_plane(
    points: np.ndarray, iterations: int = 15, max_points: int = 4000, seed: int = 0
) -> tuple[np.ndarray, float, float]:
    """The mirror plane of a template: (unit normal (3,), offset, rms residual / size).

    points (N, 3). The plane is ``normal . x = offset``; the residual is the root mean squared
    distance between reflected points and their nearest neighbours, over the bounding-box
    diagonal (about 0 for a symmetric mesh, larger for an asymmetric one).
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 4:
        raise InputError("need at least 4 points (N, 3) to find a symmetry plane")
    if len(pts) > max_points:
        pts = pts[np.random.default_rng(seed).choice(len(pts), max_points, replace=False)]
    size = float(np.linalg.norm(pts.max(0) - pts.min(0))) or 1.0
    tree = cKDTree(pts)
    center = pts.mean(0)
    _, _, axes = np.linalg.svd(pts - center, full_matrices=False)
    cands = [(a, float(a @ center)) for a in axes]
    normal, offset = min(cands, key=lambda c: _one_way(tree, pts, c[0], c[1]))
    for _ in range(iterations):
        refl = pts - 2.0 * ((pts @ normal) - offset)[:, None] * normal
        dist, idx = tree.query(refl)
        keep = dist <= np.quantile(dist, 0.8)  # robust: drop the worst-matched fifth
        p, q = pts[keep], pts[idx[keep]]
        diff = p - q  # parallel to the normal for a true mirror pair
        diff = diff[np.linalg.norm(diff, axis=1) > 1e-3 * size]
        if len(diff) < 3:
            break
        _, _, vt = np.linalg.svd(diff, full_matrices=False)
        new_normal = vt[0] * np.sign(vt[0] @ normal or 1.0)
        new_offset = float(np.median(((p + q) * 0.5) @ new_normal))
        converged = np.abs(new_normal - normal).max() < 1e-7 and abs(new_offset - offset) < 1e-7 * size
        normal, offset = new_normal, new_offset
        if converged:
            break
    rms = float(np.sqrt(_one_way(tree, pts, normal, offset))) / size
    return normal, offset, rms


def symmetric_joint_pairs(heads: np.ndarray, normal: np.ndarray, offset: float, tol: float) -> np.ndarray:
    """(P, 2) joint index pairs (l, r), l < r, that mirror each other within ``tol`` model units."""
    refl = heads - 2.0 * ((heads @ normal) - offset)[:, None] * normal
    dist, idx = cKDTree(heads).query(refl)
    pairs = [
        (j, int(i))
        for j, (d, i) in enumerate(zip(dist, idx, strict=True))
        if d <= tol and i > j and idx[i] == j
    ]
    return np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
