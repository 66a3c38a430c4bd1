"""Dual-quaternion skinning (Kavan, Collins, Zara & O'Sullivan 2007, "Skinning with dual
quaternions"), batched and differentiable, and `DualQuaternionModel`: CASA's articulation model
with it in place of linear blend skinning.

Linear blend skinning averages matrices; two bones twisted 180 degrees apart average to a matrix
that squeezes the skin onto the bone (the candy-wrapper collapse). DQS blends unit dual quaternions
``q + eps q_e`` (rotation q, ``q_e = 0.5 (0, t) q``) and normalises the blend, which is again a rigid
motion, so volume is kept at twisted joints.

Bone matrices that are not rigid (scaled rigs) are split as ``A_k = R_k S_k`` (R_k by Gram-Schmidt
on A_k's columns): the S_k are blended linearly in bind space first and the rigid parts by dual
quaternions (the paper's two-phase skinning). CASA's stretch term ``sum_k w_k L_k e_k s_k`` is
linear in the stretch vectors and is added as in LBS.
"""

from __future__ import annotations

import torch

from .model import ArticulatedModel
from .rotations import matrix_to_quat, quat_mul, quat_rotate
from .skinning import DENSE_MAX_JOINTS, stretch_offsets

Tensor = torch.Tensor


def orthonormalize(m: Tensor, eps: float = 1e-12) -> Tensor:
    """(..., 3, 3) -> the rotation whose columns are Gram-Schmidt of m's first two columns."""
    a, b = m[..., :, 0], m[..., :, 1]
    x = a / a.norm(dim=-1, keepdim=True).clamp_min(eps)
    b = b - (x * b).sum(-1, keepdim=True) * x
    y = b / b.norm(dim=-1, keepdim=True).clamp_min(eps)
    return torch.stack((x, y, torch.linalg.cross(x, y)), -1)


def dual_quaternion_skinning(
    points: Tensor, mats: Tensor, bones: Tensor, weights: Tensor,
    stretch: Tensor | None = None, endpoint: Tensor | None = None,
) -> Tensor:  # fmt: skip
    """Posed vertices by dual-quaternion blending (same signature as `linear_blend_skinning`).

    points (V, 3) or (..., V, 3) bind vertices; mats (..., J, 4, 4) skinning matrices
    ``G_k @ inverse_bind_k``; bones (V, K) long candidate bones; weights (V, K) or (..., V, K) on
    the simplex; stretch (..., J, 3) and endpoint (V, K) optional (CASA's stretchable bones).
    Returns (..., V, 3).
    """
    A, t = mats[..., :3, :3], mats[..., :3, 3]
    R = orthonormalize(A)
    S = R.transpose(-1, -2) @ A  # (..., J, 3, 3): identity for rigid bones
    q = matrix_to_quat(R)  # (..., J, 4)
    qe = 0.5 * quat_mul(torch.cat((torch.zeros_like(t[..., :1]), t), -1), q)
    with torch.no_grad():  # q and -q are one rotation: flip each candidate into the first one's hemisphere
        qk = q[..., bones, :]  # (..., V, K, 4)
        sign = torch.where((qk * qk[..., :1, :]).sum(-1) < 0, -1.0, 1.0).to(q.dtype)  # (..., V, K)
    J = mats.shape[-3]
    signed = weights * sign
    if J <= DENSE_MAX_JOINTS:
        # Blend through dense (..., V, J) weights and one matmul each, as linear_blend_skinning does.
        idx = bones.expand(signed.shape)
        dense_s = signed.new_zeros(signed.shape[:-1] + (J,)).scatter_add(-1, idx, signed)
        b = dense_s @ torch.cat((q, qe), -1)  # (..., V, 8)
        dense = weights.new_zeros(weights.shape[:-1] + (J,)).scatter_add(
            -1, bones.expand(weights.shape), weights
        )
        Sb = (dense @ S.flatten(-2)).unflatten(-1, (3, 3))  # (..., V, 3, 3)
        b0, be = b[..., :4], b[..., 4:]
    else:
        b0 = (signed[..., None] * q[..., bones, :]).sum(-2)
        be = (signed[..., None] * qe[..., bones, :]).sum(-2)
        Sb = (weights[..., None, None] * S[..., bones, :, :]).sum(-3)
    n = b0.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    c0, ce = b0 / n, be / n
    w0, cv = c0[..., :1], c0[..., 1:]
    we, ev = ce[..., :1], ce[..., 1:]
    trans = 2.0 * (w0 * ev - we * cv + torch.linalg.cross(cv, ev))  # vec(2 ce conj(c0))
    p = (Sb * points[..., None, :]).sum(-1)  # S_b p, elementwise: a bmm of 3x3s is slower
    out = quat_rotate(c0, p) + trans
    if stretch is not None:
        out = out + stretch_offsets(mats, bones, weights, stretch, endpoint)
    return out


class DualQuaternionModel(ArticulatedModel):
    """`ArticulatedModel` (stretchable bones, learnable weights, displacement field) skinned by
    dual quaternions instead of linear blending; registered as the ``dqs`` articulation model."""

    skinning = staticmethod(dual_quaternion_skinning)
