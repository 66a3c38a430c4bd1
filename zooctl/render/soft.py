"""`SoftSilhouette`: SoftRas-style differentiable silhouettes (Liu et al. 2019).

Each face f covers pixel p with probability ``D_f(p) = sigmoid(delta * d^2(p, f) / sigma)``,
``d`` the screen distance from the pixel centre to the face's boundary and ``delta`` +1 inside,
-1 outside; the silhouette is ``1 - prod_f (1 - D_f(p))``, evaluated as
``1 - exp(sum_f logsigmoid(-delta d^2 / sigma))`` for stability.

Cost follows covered pixels: a face is evaluated only on the pixels of its screen box grown by
``sqrt(sigma * ln(1 / eps))`` (beyond it ``D_f < eps``), see `zooctl.render.windows`. The per-pair
gradient is written out by hand (`_SoftCoverage`): d^2 is a minimum over the three edges of a
clamped projection, so its derivative is that of the nearest edge's residual (envelope theorem),
which saves most of autograd's memory and time.

Two implementations, selected automatically, give the same result (tested to 1e-5 on images,
gradients to 2e-4 of their scale in float32 and 1e-9 in float64, and gradcheck in float64):

- CPU float32/float64 tensors: a C++ kernel (`zooctl.render._kernels`, compiled on first use)
  loops over each face's window without materialising the pairs, vectorised over the window's
  pixels and threaded over image row bands (forward) and faces (backward). It forms the product
  ``prod_f (1 - D_f)`` directly (no log per pair); products below 1e-30 are flushed to 0, which
  moves the silhouette by < 1e-30 and each gradient term by < 1e-30 |dL/dsil| 2 d / sigma.
- CUDA tensors, or no C++ compiler: the pure-PyTorch pair path below (GPUs are fast at it).

Every pair in every window is evaluated; nothing is skipped beyond the ``eps`` window. Skipping
"saturated" interior pixels was considered and rejected: on a closed mesh the pixels along
interior mesh edges (seams) are covered with d ~ 0 by two front and two back faces, so
1 - silhouette ~ 2^-4 = 0.06 there (sigma 0.5), and their gradients are not negligible.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from . import _kernels
from .camera import Camera
from .windows import PairBudget, face_windows_int32, padded, project_faces

Tensor = torch.Tensor


def _edge_terms(tri: Tensor, px: Tensor, py: Tensor) -> tuple[Tensor, Tensor, Tensor, Tensor, Tensor]:
    """Signed-distance pieces for pairs: tri (P, 3, 2) and pixel centres (P,).

    Returns d2 (P,), inside (P,) bool, edge (P,) long index of the nearest edge, t (P,) its clamped
    projection parameter and r (P, 2) the residual p - (a + t (b - a)).
    """
    p = torch.stack((px, py), -1)  # (P, 2)
    a = tri
    e = torch.roll(tri, -1, dims=1) - a  # edges a->b, b->c, c->a: (P, 3, 2)
    rel = p[:, None, :] - a
    ee = (e * e).sum(-1).clamp_min(1e-20)
    t = ((rel * e).sum(-1) / ee).clamp(0.0, 1.0)
    r = rel - t[..., None] * e
    d2_all = (r * r).sum(-1)
    d2, edge = d2_all.min(-1)
    cross = e[..., 0] * rel[..., 1] - e[..., 1] * rel[..., 0]
    inside = ((cross >= 0).all(-1) | (cross <= 0).all(-1)) & (cross.abs().sum(-1) > 0)
    idx = edge[:, None]
    return d2, inside, edge, t.gather(1, idx)[:, 0], r.gather(1, idx[..., None].expand(-1, 1, 2))[:, 0]


class _SoftCoverage(torch.autograd.Function):
    """log(1 - D_f(p)) for every (face, pixel) pair, with a hand-written backward."""

    @staticmethod
    def forward(ctx, tri_all: Tensor, face: Tensor, px: Tensor, py: Tensor, sigma: float) -> Tensor:  # type: ignore[override]
        tri = tri_all[face]
        d2, inside, edge, t, r = _edge_terms(tri, px, py)
        sign = torch.where(inside, -1.0, 1.0).to(d2.dtype)  # = -delta
        z = sign * d2 / sigma
        out = torch.nn.functional.logsigmoid(z)
        # d out / d d2 = sigmoid(-z) * (-delta / sigma); d d2 / d a = -2 (1 - t) r, d b = -2 t r.
        g = torch.sigmoid(-z) * sign / sigma
        ctx.save_for_backward(face, edge, t, r, g)
        ctx.num_faces = tri_all.shape[0]
        return out

    @staticmethod
    def backward(ctx, grad_out: Tensor):  # type: ignore[override]
        face, edge, t, r, g = ctx.saved_tensors
        k = (grad_out * g * -2.0)[:, None] * r  # (P, 2)
        ga = k * (1.0 - t)[:, None]
        gb = k * t[:, None]
        grad = torch.zeros(ctx.num_faces * 3, 2, dtype=r.dtype, device=r.device)
        base = face * 3
        grad.index_add_(0, base + edge, ga)
        grad.index_add_(0, base + (edge + 1) % 3, gb)
        return grad.view(-1, 3, 2), None, None, None, None


class _SoftSilhouetteKernel(torch.autograd.Function):
    """CPU kernel: tri (B*F, 3, 2) -> silhouettes (B*H*W,) = 1 - exp(sum over faces of log(1 - D_f))."""

    @staticmethod
    def forward(
        ctx, tri_all: Tensor, win: Tensor, batch: int, height: int, width: int, sigma: float
    ) -> Tensor:  # type: ignore[override]
        tri = tri_all.detach().contiguous()
        F = tri.shape[0] // batch
        e = tri.new_empty(batch * height * width)  # exp(acc) = prod_f (1 - D_f)
        _kernels.kernel_for("soft_forward", tri)(tri, win, batch, F, height, width, sigma, e)
        ctx.save_for_backward(tri, win, e)
        ctx.shape = (batch, F, height, width, sigma)
        return 1.0 - e

    @staticmethod
    def backward(ctx, grad_sil: Tensor):  # type: ignore[override]
        tri, win, e = ctx.saved_tensors
        B, F, H, W, sigma = ctx.shape
        grad_sil = grad_sil.to(tri.dtype).contiguous()
        grad = torch.empty_like(tri)
        _kernels.kernel_for("soft_backward", tri)(tri, win, e, grad_sil, B, F, H, W, sigma, grad)
        return grad, None, None, None, None, None


class SoftSilhouette(nn.Module):
    """Soft silhouettes: vertices (B, V, 3), faces (F, 3), `Camera` -> (B, H, W) in [0, 1].

    ``sigma`` is in squared pixels (SoftRas's 1e-4 in NDC is ``1e-4 * (S / 2)^2``: 0.41 at 128 px);
    smaller is sharper. ``eps`` bounds the dropped tail of each face's influence. CPU tensors use
    the C++ kernel when it builds, CUDA tensors the PyTorch path (module docstring).
    """

    def __init__(
        self, image_size: int | tuple[int, int], sigma: float = 0.5, eps: float = 1e-4, device: str = "cpu"
    ):
        super().__init__()
        self.height, self.width = (image_size, image_size) if isinstance(image_size, int) else image_size
        if sigma <= 0:
            raise ValueError("sigma must be positive")
        self.sigma = float(sigma)
        self.margin = math.sqrt(self.sigma * math.log(1.0 / eps))
        self.budget = PairBudget()  # the pair path's: no read-back a call (`PairBudget`)

    def forward(self, vertices: Tensor, faces: Tensor, camera: Camera) -> Tensor:
        H, W = camera.height, camera.width
        sf = project_faces(vertices, faces, camera)
        if _kernels.kernel_for("soft_forward", sf.tri) is not None:
            win = face_windows_int32(sf, H, W, self.margin)
            return _SoftSilhouetteKernel.apply(sf.tri, win, sf.batch, H, W, self.sigma).view(sf.batch, H, W)
        pairs = self.budget.pairs(sf, H, W, self.margin)
        val = _SoftCoverage.apply(padded(sf.tri, pairs), pairs.face, pairs.px, pairs.py, self.sigma)
        n = sf.batch * H * W
        acc = torch.zeros(n + 1, dtype=val.dtype, device=val.device).index_add(0, pairs.pixel, val)
        return (1.0 - acc[:n].exp()).view(sf.batch, H, W)
