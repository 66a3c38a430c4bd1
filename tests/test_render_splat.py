"""Splatted silhouettes: close to the hard mask, differentiable, and good enough to fit a shift."""

import pytest
import torch

from zooctl.render.camera import look_at
from zooctl.render.raster import rasterize
from zooctl.render.splat import SplatSilhouette, subdivision_barycentrics
from zooctl.rig.synthetic import uv_sphere

pytestmark = pytest.mark.usefixtures("one_thread")  # see conftest


def test_barycentric_samples_are_on_the_triangle():
    for level in (1, 2, 3):
        b = subdivision_barycentrics(level)
        assert b.shape == (level * level, 3) and torch.allclose(b.sum(-1), torch.ones(len(b)))
        assert (b > 0).all()


def test_close_to_the_hard_mask_and_differentiable():
    v, f = uv_sphere(2000)
    verts = torch.as_tensor(v)[None].repeat(2, 1, 1) + torch.tensor([[[0.0, 0.0, 0.0]], [[0.4, -0.2, 0.0]]])
    verts.requires_grad_(True)
    cam = look_at([0.0, 0.0, 4.0], [0.0, 0.0, 0.0], 64, 64)
    hard = rasterize(verts.detach(), torch.as_tensor(f), cam).mask
    sil = SplatSilhouette(64)(verts, torch.as_tensor(f), cam)
    assert sil.shape == (2, 64, 64) and sil.min() >= 0 and sil.max() <= 1
    for b in range(2):
        iou = float(((sil[b] > 0.5) & hard[b]).sum() / ((sil[b] > 0.5) | hard[b]).sum())
        assert iou >= 0.9
    sil.sum().backward()
    assert torch.isfinite(verts.grad).all() and verts.grad.abs().sum() > 0


def test_recovers_a_translation():
    v, f = uv_sphere(600)
    v, f = torch.as_tensor(v), torch.as_tensor(f)
    cam = look_at([0.0, 0.0, 5.0], [0.0, 0.0, 0.0], 48, 48)
    target = rasterize((v + torch.tensor([0.3, 0.2, 0.0]))[None], f, cam).mask.float()
    render = SplatSilhouette(48, blur=1.5)
    t = torch.zeros(3, requires_grad=True)
    opt = torch.optim.Adam([t], lr=0.03)
    for _ in range(80):
        opt.zero_grad()
        ((render((v + t)[None], f, cam) - target) ** 2).mean().backward()
        opt.step()
    assert (t.detach()[:2] - torch.tensor([0.3, 0.2])).abs().max() < 0.04
