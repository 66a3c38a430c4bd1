"""Soft silhouettes: agreement with the hard mask, exact hand-written gradients, and fitting."""

import pytest
import torch

from zooctl.render.camera import look_at
from zooctl.render.raster import rasterize
from zooctl.render.soft import SoftSilhouette, _edge_terms, _SoftCoverage
from zooctl.rig.synthetic import uv_sphere

pytestmark = pytest.mark.usefixtures("one_thread")  # see conftest


def _iou(a, b):
    return float((a & b).sum() / (a | b).sum())


def _sphere(faces=600, dtype=torch.float32):
    v, f = uv_sphere(faces)
    return torch.as_tensor(v, dtype=dtype), torch.as_tensor(f)


def test_small_sigma_matches_the_hard_mask():
    v, f = _sphere(1200)
    cam = look_at([[0.0, 0.3, 3.5], [2.0, 1.0, 2.5]], [0.2, 0.0, 0.0], 64, 80)
    verts = torch.stack((v, v * torch.tensor([1.3, 0.8, 1.0]))) + torch.tensor([0.3, 0.0, 0.0])
    hard = rasterize(verts, f, cam).mask
    soft = SoftSilhouette((64, 80), sigma=0.02)(verts, f, cam)
    assert soft.shape == (2, 64, 80) and 0 <= soft.min() and soft.max() <= 1
    for b in range(2):
        assert _iou(soft[b] > 0.5, hard[b]) >= 0.95


def _reference_coverage(tri_all, face, px, py, sigma):
    """The same quantity with plain autograd (no hand-written backward)."""
    tri = tri_all[face]
    p = torch.stack((px, py), -1)
    e = torch.roll(tri, -1, dims=1) - tri
    rel = p[:, None, :] - tri
    t = ((rel * e).sum(-1) / (e * e).sum(-1)).clamp(0, 1)
    d2 = ((rel - t[..., None] * e) ** 2).sum(-1).min(-1).values
    _, inside, _, _, _ = _edge_terms(tri.detach(), px, py)
    sign = torch.where(inside, -1.0, 1.0).to(d2.dtype)
    return torch.nn.functional.logsigmoid(sign * d2 / sigma)


def test_hand_written_backward_is_exact():
    g = torch.Generator().manual_seed(0)
    tri = (torch.rand(5, 3, 2, generator=g, dtype=torch.float64) * 8).requires_grad_(True)
    face = torch.arange(5).repeat_interleave(40)
    px = torch.rand(200, generator=g, dtype=torch.float64) * 8
    py = torch.rand(200, generator=g, dtype=torch.float64) * 8
    assert torch.autograd.gradcheck(lambda t: _SoftCoverage.apply(t, face, px, py, 1.5), (tri,))
    w = torch.randn(200, generator=g, dtype=torch.float64)
    (ga,) = torch.autograd.grad((_SoftCoverage.apply(tri, face, px, py, 1.5) * w).sum(), tri)
    (gb,) = torch.autograd.grad((_reference_coverage(tri, face, px, py, 1.5) * w).sum(), tri)
    assert torch.allclose(ga, gb, atol=1e-10)


def test_recovers_translation_and_scale_from_masks():
    v, f = _sphere(400)
    cam = look_at([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], 48, 48)
    coarse, fine = (
        SoftSilhouette(48, sigma=1.0),
        SoftSilhouette(48, sigma=0.05),
    )  # coarse to fine: sigma dilates
    true_t, true_s = torch.tensor([0.35, -0.25, 0.0]), torch.tensor(0.8)
    with torch.no_grad():
        target = rasterize((v * true_s + true_t)[None], f, cam).mask.float()
    t = torch.zeros(3, requires_grad=True)
    log_s = torch.zeros((), requires_grad=True)
    opt = torch.optim.Adam([t, log_s], lr=0.03)
    for i in range(150):
        opt.zero_grad()
        sil = (coarse if i < 70 else fine)((v * log_s.exp() + t)[None], f, cam)
        ((sil - target) ** 2).mean().backward()
        t.grad[2] = 0.0  # depth and scale are ambiguous from one view: fit in-plane position and size
        opt.step()
    assert (t.detach()[:2] - true_t[:2]).abs().max() < 0.03
    assert abs(float(log_s.detach().exp()) - 0.8) < 0.03
