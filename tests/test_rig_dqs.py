"""Dual-quaternion skinning: exact for rigid motions, gradchecked in float64, and free of the
candy-wrapper collapse that linear blend skinning shows at a 180-degree twist."""

from __future__ import annotations

import math

import torch

from zooctl.plugins import get_registry
from zooctl.rig.dqs import dual_quaternion_skinning
from zooctl.rig.rotations import axis_angle_to_quat, quat_to_matrix
from zooctl.rig.skinning import linear_blend_skinning
from zooctl.rig.synthetic import tube_asset


def _rigid(aa: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    m = torch.eye(4, dtype=aa.dtype).repeat(aa.shape[:-1] + (1, 1))
    m[..., :3, :3] = quat_to_matrix(axis_angle_to_quat(aa))
    m[..., :3, 3] = t
    return m


def test_one_rigid_motion_is_reproduced_exactly_and_matches_lbs():
    gen = torch.Generator().manual_seed(0)
    pts = torch.randn(30, 3, generator=gen, dtype=torch.float64)
    bones = torch.randint(0, 4, (30, 3), generator=gen)
    w = torch.softmax(torch.randn(30, 3, generator=gen, dtype=torch.float64), -1)
    one = _rigid(
        torch.randn(2, 1, 3, generator=gen, dtype=torch.float64), torch.randn(2, 1, 3, dtype=torch.float64)
    )
    mats = one.expand(2, 4, 4, 4)  # every bone moves the same way: any blend is that motion
    dq = dual_quaternion_skinning(pts, mats, bones, w)
    lbs = linear_blend_skinning(pts, mats, bones, w)
    assert dq.shape == (2, 30, 3)
    torch.testing.assert_close(dq, lbs, atol=1e-10, rtol=0)


def test_gradcheck_float64():
    gen = torch.Generator().manual_seed(1)
    pts = torch.randn(5, 3, generator=gen, dtype=torch.float64)
    bones = torch.tensor([[0, 1], [1, 2], [2, 0], [0, 2], [1, 0]])
    aa = (0.7 * torch.randn(2, 3, 3, generator=gen, dtype=torch.float64)).requires_grad_()
    t = torch.randn(2, 3, 3, generator=gen, dtype=torch.float64).requires_grad_()
    logits = torch.randn(5, 2, generator=gen, dtype=torch.float64).requires_grad_()
    stretch = (0.1 * torch.randn(3, 3, generator=gen, dtype=torch.float64)).requires_grad_()
    endpoint = torch.rand(5, 2, generator=gen, dtype=torch.float64)

    def f(aa, t, logits, stretch):
        mats = _rigid(aa, t)
        mats = mats * torch.tensor([1.3, 1.3, 1.3, 1.0], dtype=mats.dtype)[:, None]  # a scaled rig
        return dual_quaternion_skinning(pts, mats, bones, torch.softmax(logits, -1), stretch, endpoint)

    assert torch.autograd.gradcheck(f, (aa, t, logits, stretch), eps=1e-6, atol=1e-6)


def test_no_candy_wrapper_at_a_180_degree_twist():
    """Twist the second bone of a tube 180 degrees about its own axis: LBS squeezes the blended
    ring at the joint onto the bone, DQS keeps its radius."""
    radius = 0.15
    asset = tube_asset(bones=2, bone_length=1.0, radius=radius, rings_per_bone=8, blend=0.25)
    reg = get_registry()
    rot = torch.tensor([[1.0, 0, 0, 0], [math.cos(math.pi / 2), math.sin(math.pi / 2), 0, 0]])  # (J, 4)
    radii = {}
    for name in ("lbs", "dqs"):
        model = reg.get("articulation_model", name).create(asset=asset, stretch=False, displacement=False)
        v = model(rot[None]).vertices[0].detach()
        joint_ring = (v[:, 0] - 1.0).abs() < 1e-4  # the ring at the joint, weights 0.5 / 0.5
        assert joint_ring.sum() == 16
        radii[name] = float(v[joint_ring][:, 1:].norm(dim=-1).mean())
    assert radii["lbs"] < 0.05 * radius  # collapsed onto the bone
    assert abs(radii["dqs"] - radius) < 1e-4 * radius  # kept


def test_dense_and_gathered_blends_agree(monkeypatch):
    """Rigs of up to DENSE_MAX_JOINTS joints blend through dense weights, larger ones by gathering."""
    import zooctl.rig.dqs as dqs

    gen = torch.Generator().manual_seed(2)
    pts = torch.randn(40, 3, generator=gen, dtype=torch.float64)
    bones = torch.randint(0, 6, (40, 3), generator=gen)
    w = torch.softmax(torch.randn(40, 3, generator=gen, dtype=torch.float64), -1)
    mats = _rigid(
        2 * torch.randn(4, 6, 3, generator=gen, dtype=torch.float64),
        torch.randn(4, 6, 3, dtype=torch.float64),
    )
    dense = dqs.dual_quaternion_skinning(pts, mats, bones, w)
    monkeypatch.setattr(dqs, "DENSE_MAX_JOINTS", 0)
    torch.testing.assert_close(dqs.dual_quaternion_skinning(pts, mats, bones, w), dense, atol=1e-12, rtol=0)
