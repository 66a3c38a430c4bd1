"""How far apart two versions of one rig pose their vertices: the check behind export round trips.

`posed_error_bound` bounds the posed-vertex difference over *every* frame of every clip without
skinning every frame: with the same bind-space vertices v and weights w, the two posed positions
of a vertex differ by ``sum_k w_k (M_k - M'_k) [v, 1]``, whose length is at most
``max_k (||A_k - A'_k||_F |v| + |t_k - t'_k|)`` over the joints k with weight (M = [A | t] the
skinning matrices), plus the effect of the vertex and weight differences themselves.
`posed_difference` skins chosen frames literally.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..asset import RiggedAsset
from ..errors import InputError


def joint_permutation(a: RiggedAsset, b: RiggedAsset) -> np.ndarray:
    """(J,) index into b's joints of each of a's joints, matched by name."""
    index = {n: i for i, n in enumerate(b.joint_names)}
    missing = [n for n in a.joint_names if n not in index]
    if missing or a.num_joints != b.num_joints:
        raise InputError(f"the rigs differ: joints {missing[:3]} of {a.name!r} are missing from {b.name!r}")
    return np.array([index[n] for n in a.joint_names])


def posed_error_bound(
    a: RiggedAsset, b: RiggedAsset, clips: Sequence[str] | None = None, include_rest: bool = True
) -> float:
    """Upper bound of max |posed_a - posed_b| over every frame of the clips (default: all of a's),
    and the rest pose when ``include_rest``. Vertices must correspond one to one (same order).
    """
    if a.num_vertices != b.num_vertices:
        raise InputError(f"vertex counts differ: {a.num_vertices} vs {b.num_vertices}")
    perm = joint_permutation(a, b)
    wa, wb = a.skin_weights_dense(), b.skin_weights_dense()[:, perm]
    used = np.nonzero((wa > 0).any(0) | (wb > 0).any(0))[0]
    vlen = float(np.linalg.norm(a.vertices.astype(np.float64), axis=1).max())
    dv = float(np.linalg.norm(a.vertices.astype(np.float64) - b.vertices, axis=1).max())
    dw = float(np.abs(wa - wb).sum(1).max())
    worst = 0.0
    for name in [None, *(a.clips if clips is None else clips)][0 if include_rest else 1 :]:
        if name is not None and name not in b.clips:
            raise InputError(f"clip {name!r} is missing after the round trip")
        la = a.rest_local if name is None else a.clips[name].local_matrices()
        lb = b.rest_local if name is None else b.clips[name].local_matrices()
        if la.shape[:-3] != lb.shape[:-3]:
            raise InputError(f"clip {name!r} has {la.shape[0]} frames before and {lb.shape[0]} after")
        ma = a.skinning_matrices(la)[..., used, :, :]
        mb = b.skinning_matrices(lb)[..., perm, :, :][..., used, :, :]
        d = ma - mb
        # The Frobenius norm bounds the spectral norm and needs no SVD.
        lin = np.sqrt((d[..., :3, :3] ** 2).sum((-2, -1)))
        trans = np.linalg.norm(d[..., :3, 3], axis=-1)
        dm = float((lin * vlen + trans).max())
        # |M_b| bounds how far a vertex or weight difference can carry.
        mb_lin_all = np.sqrt((mb[..., :3, :3] ** 2).sum((-2, -1)))
        mb_norm = float((mb_lin_all * vlen + np.linalg.norm(mb[..., :3, 3], axis=-1)).max())
        mb_lin = float(mb_lin_all.max())
        worst = max(worst, dm + dw * mb_norm + dv * mb_lin)
    return worst


def posed_difference(a: RiggedAsset, b: RiggedAsset, clip: str | None, frames: Sequence[int]) -> float:
    """max |posed_a - posed_b| over the given frames of a clip (None: the rest pose)."""
    fr = np.asarray(list(frames), dtype=int)
    pa = a.pose(clip, fr) if clip is not None else a.pose(None)
    pb = b.pose(clip, fr) if clip is not None else b.pose(None)
    return float(np.abs(pa - pb).max())
