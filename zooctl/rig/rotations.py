"""Rotation utilities in PyTorch, batched over any leading ``...`` dimensions.

Conventions match `zooctl.geometry`: quaternions are (w, x, y, z) Hamilton quaternions, matrices
act on column vectors. The 6D representation (Zhou et al. 2019) is the first two *columns* of the
rotation matrix, concatenated: ``(..., 6) = [m[:, 0], m[:, 1]]``.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from ..geometry import hamilton

Tensor = torch.Tensor


def quat_identity(
    *shape: int, dtype: torch.dtype = torch.float32, device: torch.device | str | None = None
) -> Tensor:
    """(*shape, 4) identity quaternions."""
    q = torch.zeros(*shape, 4, dtype=dtype, device=device)
    q[..., 0] = 1.0
    return q


def quat_normalize(q: Tensor, eps: float = 1e-12) -> Tensor:
    """(..., 4) -> (..., 4) unit quaternions (differentiable; a zero input stays near zero)."""
    return q / q.norm(dim=-1, keepdim=True).clamp_min(eps)


def quat_mul(a: Tensor, b: Tensor) -> Tensor:
    """Hamilton product a * b of (..., 4) quaternions (broadcasting): rotate by b, then by a."""
    return torch.stack(hamilton(a.unbind(-1), b.unbind(-1)), -1)


def quat_conjugate(q: Tensor) -> Tensor:
    """(..., 4) conjugate; the inverse of a unit quaternion."""
    return q * q.new_tensor([1.0, -1.0, -1.0, -1.0])


def quat_inverse(q: Tensor, eps: float = 1e-12) -> Tensor:
    """(..., 4) inverse of any non-zero quaternion: conj(q) / |q|^2."""
    return quat_conjugate(q) / (q * q).sum(-1, keepdim=True).clamp_min(eps)


def quat_rotate(q: Tensor, v: Tensor) -> Tensor:
    """Rotate (..., 3) vectors by unit quaternions (..., 4) (broadcasting)."""
    w = q[..., :1]
    u = q[..., 1:]
    t = 2.0 * torch.linalg.cross(u, v)
    return v + w * t + torch.linalg.cross(u, t)


def quat_to_matrix(q: Tensor) -> Tensor:
    """(..., 4) wxyz (normalised here) -> (..., 3, 3) rotation matrices.

    Each entry is the usual ``1 - 2 (y^2 + z^2)``, ``2 (xy - wz)``, ... as one product of the
    quaternion's outer product with a constant (16, 9) table: a few large operators instead of
    some forty small ones (forward and backward), which a GPU pays for in kernel launches."""
    q = quat_normalize(q)
    table, ident = _quat_matrix_table(q.dtype, q.device)
    outer = (q[..., :, None] * q[..., None, :]).reshape(*q.shape[:-1], 16)
    return (outer @ table + ident).reshape(q.shape[:-1] + (3, 3))


_TABLES: dict[tuple[torch.dtype, torch.device], tuple[Tensor, Tensor]] = {}


def _quat_matrix_table(dtype: torch.dtype, device: torch.device) -> tuple[Tensor, Tensor]:
    """(16, 9) weights of the products q_a q_b (row 4a + b, wxyz) in each entry of the row-major
    rotation matrix, and (9,) the identity the constant terms add."""
    key = (dtype, device)
    if key not in _TABLES:
        w, x, y, z = range(4)
        terms = {  # entry: ((a, b, coefficient), ...)
            0: ((y, y, -2), (z, z, -2)), 1: ((x, y, 2), (w, z, -2)), 2: ((x, z, 2), (w, y, 2)),
            3: ((x, y, 2), (w, z, 2)), 4: ((x, x, -2), (z, z, -2)), 5: ((y, z, 2), (w, x, -2)),
            6: ((x, z, 2), (w, y, -2)), 7: ((y, z, 2), (w, x, 2)), 8: ((x, x, -2), (y, y, -2)),
        }  # fmt: skip
        table = torch.zeros(16, 9, dtype=torch.float64)
        for entry, products in terms.items():
            for a, b, c in products:
                table[4 * a + b, entry] += c
        ident = torch.eye(3, dtype=torch.float64).reshape(9)
        _TABLES[key] = (table.to(device=device, dtype=dtype), ident.to(device=device, dtype=dtype))
    return _TABLES[key]


def matrix_to_quat(m: Tensor) -> Tensor:
    """(..., 3, 3) rotation matrices -> (..., 4) wxyz with w >= 0.

    Shepperd's method, vectorised: of the four candidate formulas the one with the largest pivot
    is used, so the result (and its gradient) is well conditioned for every rotation.
    """
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    piv = torch.stack(
        (1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22), -1
    )
    d21, d02, d10 = m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]
    s01, s02, s12 = m[..., 0, 1] + m[..., 1, 0], m[..., 0, 2] + m[..., 2, 0], m[..., 1, 2] + m[..., 2, 1]
    cand = torch.stack(
        (
            torch.stack((piv[..., 0], d21, d02, d10), -1),
            torch.stack((d21, piv[..., 1], s01, s02), -1),
            torch.stack((d02, s01, piv[..., 2], s12), -1),
            torch.stack((d10, s02, s12, piv[..., 3]), -1),
        ),
        -2,
    )  # (..., 4, 4): row k is 4 * sqrt(piv_k / 4) * q
    k = piv.argmax(-1, keepdim=True)
    best = torch.gather(cand, -2, k[..., None].expand(k.shape[:-1] + (1, 4))).squeeze(-2)
    q = best / (2.0 * torch.gather(piv, -1, k).clamp_min(1e-12).sqrt())
    q = torch.where(q[..., :1] < 0, -q, q)
    return quat_normalize(q)


def rot6d_to_matrix(d6: Tensor) -> Tensor:
    """(..., 6) -> (..., 3, 3) by Gram-Schmidt on the two columns (Zhou et al. 2019)."""
    a1, a2 = d6[..., :3], d6[..., 3:]
    b1 = F.normalize(a1, dim=-1)
    b2 = F.normalize(a2 - (b1 * a2).sum(-1, keepdim=True) * b1, dim=-1)
    b3 = torch.cross(b1, b2, dim=-1)
    return torch.stack((b1, b2, b3), -1)


def matrix_to_rot6d(m: Tensor) -> Tensor:
    """(..., 3, 3) -> (..., 6): the first two columns."""
    return torch.cat((m[..., :, 0], m[..., :, 1]), -1)


def axis_angle_to_quat(aa: Tensor) -> Tensor:
    """(..., 3) rotation vectors (axis * angle in radians) -> (..., 4) wxyz.

    Uses sin(x/2)/x with its Taylor expansion near zero so the gradient at the identity is exact.
    """
    angle = aa.norm(dim=-1, keepdim=True)
    half = 0.5 * angle
    small = angle < 1e-4
    safe = torch.where(small, torch.ones_like(angle), angle)
    k = torch.where(small, 0.5 - angle * angle / 48.0, torch.sin(half) / safe)
    return torch.cat((torch.cos(half), aa * k), -1)


def quat_to_axis_angle(q: Tensor) -> Tensor:
    """(..., 4) unit wxyz -> (..., 3) rotation vectors with angle in [0, pi] (q and -q agree)."""
    q = torch.where(q[..., :1] < 0, -q, q)
    v = q[..., 1:]
    s = v.norm(dim=-1, keepdim=True)
    angle = 2.0 * torch.atan2(s, q[..., :1])
    small = s < 1e-6
    k = torch.where(
        small, 2.0 / q[..., :1].clamp_min(1e-12), angle / torch.where(small, torch.ones_like(s), s)
    )
    return v * k


def quat_angle(a: Tensor, b: Tensor) -> Tensor:
    """(...) rotation angle in radians between unit quaternions a and b (sign-invariant)."""
    d = (a * b).sum(-1).abs().clamp(max=1.0)
    return 2.0 * torch.acos(d)
