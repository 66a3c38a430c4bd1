"""Faster forms of fit-step terms against the plain expressions they replace, on random inputs."""

from __future__ import annotations

import pytest
import torch
import torch.nn.functional as F

from zooctl.fit.losses import flow_loss


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_flow_loss_matches_the_per_pixel_sum(dtype):
    g = torch.Generator().manual_seed(0)
    B, h, w = 3, 17, 23
    rendered = (3 * torch.randn(B, h, w, 2, generator=g, dtype=torch.float64)).to(dtype).requires_grad_()
    observed = (3 * torch.randn(B, h, w, 2, generator=g, dtype=torch.float64)).to(dtype)
    mask = torch.rand(B, h, w, generator=g) > 0.3
    valid = torch.rand(B, h, w, generator=g) > 0.2
    got = flow_loss(rendered, mask, observed, valid)
    (g_got,) = torch.autograd.grad(got, rendered)
    m = (mask & valid).to(dtype)
    ref = (F.smooth_l1_loss(rendered, observed, reduction="none", beta=1.0).sum(-1) * m).sum() / m.sum()
    (g_ref,) = torch.autograd.grad(ref, rendered)
    tol = 1e-6 if dtype == torch.float32 else 1e-12
    torch.testing.assert_close(got, ref, rtol=tol, atol=0)
    torch.testing.assert_close(g_got, g_ref, rtol=tol, atol=tol * float(g_ref.abs().max()))
    assert float(got.detach()) > 0.5  # large errors (the linear part of the Huber loss) as well as small ones
