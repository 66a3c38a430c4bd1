"""The fit's fast skinning paths against the general ones they replace, on random inputs: values and
gradients to float64 rounding.

- `linear_blend_skinning` with weights shared by every pose (the fit's case) blends all poses in one
  product; the same weights given per pose take the batched dense path.
- `ArticulatedModel` folds the global scale and root rotation into the LBS matrices; a model whose
  skinning is another function (here LBS behind a wrapper) scales, turns and displaces the skinned
  vertices one step after another.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch

from zooctl.rig.model import ArticulatedModel
from zooctl.rig.rotations import quat_normalize
from zooctl.rig.skinning import linear_blend_skinning
from zooctl.rig.synthetic import tube_asset


@pytest.mark.parametrize("batch", [(6,), (2, 3), ()])
@pytest.mark.parametrize("stretch_batched", [False, True])
def test_shared_weights_skinning_matches_per_pose_weights(batch, stretch_batched):
    g = torch.Generator().manual_seed(len(batch) + 10 * stretch_batched)
    V, J, K = 57, 9, 3
    f64 = {"generator": g, "dtype": torch.float64}
    points = torch.randn(V, 3, **f64)
    mats = torch.randn(*batch, J, 4, 4, **f64).requires_grad_()
    bones = torch.randint(0, J, (V, K), generator=g)
    bones[0] = torch.tensor([2, 2, 5])  # a repeated candidate: its weights add up
    logits = torch.randn(V, K, **f64).requires_grad_()
    stretch = torch.randn(*(batch if stretch_batched else ()), J, 3, **f64).requires_grad_()
    endpoint = torch.rand(V, K, **f64)
    runs = []
    for per_pose in (False, True):
        w = torch.softmax(logits, -1)
        if per_pose:  # (..., V, K): the general dense path
            w = w.expand(*batch, V, K) if batch else w[None]
        out = linear_blend_skinning(points, mats, bones, w, stretch, endpoint)
        out = out if batch or not per_pose else out[0]
        grad = torch.randn(out.shape, generator=torch.Generator().manual_seed(5), dtype=torch.float64)
        runs.append((out, *torch.autograd.grad((out * grad).sum(), (mats, logits, stretch))))
    assert runs[0][0].shape == (*batch, V, 3)
    for name, fast, ref in zip(("vertices", "mats", "logits", "stretch"), *runs, strict=True):
        torch.testing.assert_close(fast, ref, rtol=1e-12, atol=1e-12, msg=name)


class _WrappedSkinning(ArticulatedModel):
    """The same LBS through another function object: the model's general (unfolded) path."""

    skinning = staticmethod(lambda *args: linear_blend_skinning(*args))


def _models(seed: int):
    asset = tube_asset(bones=3)
    fast, plain = (cls(asset, hidden=16, dtype=torch.float64) for cls in (ArticulatedModel, _WrappedSkinning))
    plain.load_state_dict(fast.state_dict())
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():  # away from the fresh model's zeros, so every term counts
        for a, b in zip(fast.parameters(), plain.parameters(), strict=True):
            a.copy_(a + 0.2 * torch.randn(a.shape, generator=g, dtype=a.dtype))
            b.copy_(a)
    return fast, plain


@pytest.mark.parametrize("root", [True, False])
def test_folded_lbs_model_matches_the_general_path(root):
    fast, plain = _models(seed=3)
    g = torch.Generator().manual_seed(4)
    B, J = 5, fast.num_joints
    rot = quat_normalize(fast.rest_rotation + 0.3 * torch.randn(B, J, 4, generator=g, dtype=torch.float64))
    rr = quat_normalize(torch.randn(B, 4, generator=g, dtype=torch.float64)) if root else None
    rt = torch.randn(B, 3, generator=g, dtype=torch.float64)
    runs = []
    for model in (fast, plain):
        model.zero_grad()
        pose = model(rot, rr, rt)
        gv = torch.randn(pose.vertices.shape, generator=torch.Generator().manual_seed(6), dtype=torch.float64)
        gj = torch.randn(pose.joints.shape, generator=torch.Generator().manual_seed(7), dtype=torch.float64)
        ((pose.vertices * gv).sum() + (pose.joints * gj).sum()).backward()
        runs.append((pose, {n: p.grad.clone() for n, p in model.named_parameters()}))
    (pf, gf), (pp, gp) = runs
    torch.testing.assert_close(pf.vertices, pp.vertices, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(pf.joints, pp.joints, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(pf.transforms, pp.transforms, rtol=0, atol=0)
    assert gf.keys() == gp.keys() and len(gf) > 4
    for name in gf:
        torch.testing.assert_close(gf[name], gp[name], rtol=1e-10, atol=1e-12, msg=name)
    assert float(np.abs(gf["log_scale"].numpy())) > 0  # the folded scale still gets its gradient


def test_folded_lbs_model_at_rest_without_a_batch():
    fast, plain = _models(seed=8)
    with torch.no_grad():
        a, b = fast(), plain()
    assert a.vertices.shape == (fast.num_vertices, 3) and a.joints.shape == (fast.num_joints, 3)
    torch.testing.assert_close(a.vertices, b.vertices, rtol=1e-12, atol=1e-12)
    torch.testing.assert_close(a.joints, b.joints, rtol=1e-12, atol=1e-12)
