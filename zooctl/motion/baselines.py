"""Baselines for the motion prior, trained on the same windows and sampled the same way.

- `RetrievalBaseline`: "generates" by returning training windows of the nearest skeleton (the
  same skeleton when it has training clips): the upper bound on realism, zero novelty.
- `PCABaseline`: per skeleton, a Gaussian over the top principal components of flattened 6D
  windows; samples are decoded back to rotations by Gram-Schmidt.

Both take and return windows (N, T, J, 4) of rotations relative to rest (see `dataset`).
"""

from __future__ import annotations

from collections import defaultdict

import numpy as np

from ..errors import InputError
from ..geometry import matrix_to_quat, quat_to_matrix
from .dataset import matrix_to_rot6d
from .skeleton import Skeleton


def rot6d_to_matrix_np(d6: np.ndarray) -> np.ndarray:
    """(..., 6) -> (..., 3, 3), numpy Gram-Schmidt (same convention as `zooctl.rig.rotations`)."""
    a1, a2 = d6[..., :3], d6[..., 3:]
    b1 = a1 / np.maximum(np.linalg.norm(a1, axis=-1, keepdims=True), 1e-12)
    a2 = a2 - (b1 * a2).sum(-1, keepdims=True) * b1
    b2 = a2 / np.maximum(np.linalg.norm(a2, axis=-1, keepdims=True), 1e-12)
    return np.stack([b1, b2, np.cross(b1, b2)], -1)


class _PerSkeleton:
    def __init__(self) -> None:
        self.windows: dict[str, list[np.ndarray]] = defaultdict(list)
        self.skeletons: dict[str, Skeleton] = {}

    def add(self, skeleton: Skeleton, windows: np.ndarray) -> None:
        if len(windows):
            self.skeletons[skeleton.key] = skeleton
            self.windows[skeleton.key].append(np.asarray(windows))

    def nearest(self, skeleton: Skeleton) -> str:
        """The key of the trained skeleton closest to ``skeleton``: the same key, else the same
        joint count with the nearest normalised rest pose."""
        if skeleton.key in self.skeletons:
            return skeleton.key
        same = [k for k, s in self.skeletons.items() if s.num_joints == skeleton.num_joints]
        if not same:
            raise InputError(
                f"the baseline has no training data for a {skeleton.num_joints}-joint skeleton like {skeleton.key!r}"
            )
        return min(
            same,
            key=lambda k: float(np.abs(self.skeletons[k].rest_positions - skeleton.rest_positions).sum()),
        )


class RetrievalBaseline(_PerSkeleton):
    name = "retrieval"

    def sample(self, skeleton: Skeleton, n: int, seed: int = 0) -> np.ndarray:
        pool = np.concatenate(self.windows[self.nearest(skeleton)])
        rng = np.random.default_rng(seed)
        return pool[rng.choice(len(pool), n, replace=len(pool) < n)]


class PCABaseline(_PerSkeleton):
    name = "pca"

    def __init__(self, components: int = 32) -> None:
        super().__init__()
        self.components = components
        self._fit: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, tuple[int, ...]]] = {}

    def _model(self, key: str):
        if key not in self._fit:
            w = np.concatenate(self.windows[key])
            x = matrix_to_rot6d(quat_to_matrix(w)).reshape(len(w), -1)
            mean = x.mean(0)
            _, s, vt = np.linalg.svd(x - mean, full_matrices=False)
            k = min(self.components, len(s))
            std = s[:k] / np.sqrt(max(1, len(w) - 1))
            self._fit[key] = (mean, vt[:k], std, w.shape[1:3])
        return self._fit[key]

    def sample(self, skeleton: Skeleton, n: int, seed: int = 0, spread: float = 1.0) -> np.ndarray:
        """n windows; ``spread`` scales the Gaussian's standard deviations (1: the data's)."""
        mean, basis, std, (T, J) = self._model(self.nearest(skeleton))
        rng = np.random.default_rng(seed)
        x = mean + (rng.standard_normal((n, len(std))) * std * spread) @ basis
        return matrix_to_quat(rot6d_to_matrix_np(x.reshape(n, T, J, 6)))
