"""Ground contact, 3D smoothness, edge stretch and gait symmetry, the fit's terms beyond silhouettes (`zooctl.fit.losses`): what
each costs, where its gradient goes, and that a fit computes them only when weighted."""

from __future__ import annotations

import json
import math

import pytest
import torch
from fit_helpers import tiny_overrides

from zooctl.fit.config import FitConfig
from zooctl.fit.losses import (
    body_frame,
    edge_log_stretch,
    edge_stretch_loss,
    foot_sliding_loss,
    gait_symmetry_loss,
    ground_height,
    lowest_heights,
    mesh_edges,
    sinking_loss,
    vertex_acceleration_loss,
)
from zooctl.rig.synthetic import tube_asset

SIZE = 2.0


def _feet(T: int = 4, lift: float = 0.5) -> torch.Tensor:
    """(T, 6, 3) a body in its root frame: four foot vertices on the ground (y = 0) and two
    ``lift`` above it, still over the frames."""
    v = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 0, 1], [1, 0, 1], [0.5, lift, 0.5], [0.5, lift + 0.3, 0.2]])
    return v[None].repeat(T, 1, 1)


def test_body_frame_undoes_the_root_transform():
    g = torch.Generator().manual_seed(0)
    body = torch.randn(3, 5, 3, generator=g, dtype=torch.float64)
    q = torch.nn.functional.normalize(torch.randn(3, 4, generator=g, dtype=torch.float64), dim=-1)
    t = torch.randn(3, 3, generator=g, dtype=torch.float64)
    from zooctl.rig.rotations import quat_to_matrix

    world = (quat_to_matrix(q)[:, None] @ body[..., None]).squeeze(-1) + t[:, None]
    assert torch.allclose(body_frame(world, q, t), body, atol=1e-12)


def test_the_ground_is_the_median_lowest_height():
    """One frame dipping low or jumping high does not move the ground."""
    lowest = torch.tensor([0.0, 0.0, -0.4, 0.0, 0.9])
    assert ground_height(lowest).item() == 0.0
    assert torch.equal(lowest_heights(_feet(2)), torch.zeros(2))


def test_standing_costs_nothing_and_sinking_costs_more_the_deeper():
    feet = _feet()
    assert sinking_loss(feet, 0.0, SIZE).item() == 0.0
    costs = []
    for depth in (0.05, 0.2):
        v = feet.clone()
        v[2, 0, 1] = -depth  # one foot vertex of one frame below the ground
        costs.append(sinking_loss(v, 0.0, SIZE).item())
    assert costs[0] == pytest.approx((0.05 / SIZE) ** 2)
    assert 0 < costs[0] < costs[1]


def test_sinking_pushes_up_only_what_is_below():
    v = _feet().clone()
    v[1, 2, 1] = -0.1
    v.requires_grad_(True)
    sinking_loss(v, 0.0, SIZE).backward()
    assert v.grad[1, 2, 1] < 0  # descending raises it
    v.grad[1, 2, 1] = 0.0
    assert torch.count_nonzero(v.grad) == 0


def test_a_still_foot_costs_nothing_and_a_sliding_one_more():
    feet = _feet()
    assert foot_sliding_loss(feet, 0.0, SIZE).item() == 0.0
    costs = []
    for speed in (0.02, 0.1):
        v = feet.clone()
        v[:, 0, 0] += speed * torch.arange(4.0)  # one foot vertex slides along x on the ground
        costs.append(foot_sliding_loss(v, 0.0, SIZE).item())
    assert 0 < costs[0] < costs[1]
    # Lifted vertices may move freely, and so may a foot rising straight off the ground.
    v = feet.clone()
    v[:, 4:, 0] += 0.3 * torch.arange(4.0)[:, None]
    v[:, 1, 1] += 0.01 * torch.arange(4.0)
    assert foot_sliding_loss(v, 0.0, SIZE).item() == 0.0


def test_sliding_gradient_holds_the_foot_in_place():
    v = _feet().clone()
    v[:, 0, 0] += 0.05 * torch.arange(4.0)
    v.requires_grad_(True)
    foot_sliding_loss(v, 0.0, SIZE).backward()
    g = v.grad[:, 0, 0]
    assert g[0] < 0 and g[-1] > 0  # descending moves the first frame's foot forward, the last one's back
    assert torch.count_nonzero(v.grad[:, 4:]) == 0  # nothing off the ground


def test_a_smooth_trajectory_costs_less_than_a_jittered_one():
    t = torch.linspace(0, 1, 12)
    path = torch.stack((torch.sin(t), 0.3 * t, torch.cos(t)), -1)  # (12, 3)
    verts = path[:, None] + torch.randn(1, 20, 3, generator=torch.Generator().manual_seed(1))
    line = verts.clone()
    line[:] = verts[0] + 0.1 * torch.arange(12.0)[:, None, None]  # constant velocity: no acceleration
    assert vertex_acceleration_loss(line, SIZE).item() == pytest.approx(0.0, abs=1e-10)
    jitter = verts + 0.02 * torch.randn(verts.shape, generator=torch.Generator().manual_seed(2))
    smooth, rough = vertex_acceleration_loss(verts, SIZE), vertex_acceleration_loss(jitter, SIZE)
    assert 0 < smooth.item() < rough.item()
    # Relative to the body size: the same motion at twice the scale costs the same.
    assert vertex_acceleration_loss(2 * jitter, 2 * SIZE).item() == pytest.approx(rough.item(), rel=1e-5)
    j = jitter.clone().requires_grad_(True)
    vertex_acceleration_loss(j, SIZE).backward()
    assert torch.isfinite(j.grad).all() and j.grad.abs().sum() > 0
    assert vertex_acceleration_loss(jitter[:2], SIZE).item() == 0.0  # under three frames


def test_gradients_reach_the_root_and_joints_through_the_posed_model():
    """Posed by the articulation model, each term's gradient flows to the joint rotations; the
    acceleration's to the root transform too (the ground lives in the root frame: none there)."""
    from zooctl.rig.model import ArticulatedModel

    model = ArticulatedModel(tube_asset(bones=3, name="tube"))
    T = 4
    g = torch.Generator().manual_seed(0)
    rot = model.rest_rotation.detach()[None].repeat(T, 1, 1)
    rot = (rot + 0.2 * torch.randn(rot.shape, generator=g)).requires_grad_(True)
    root_q = torch.tensor([[math.cos(0.3), math.sin(0.3), 0.0, 0.0]]).repeat(T, 1).requires_grad_(True)
    root_t = (0.1 * torch.randn(T, 3, generator=g)).requires_grad_(True)
    verts = model(rot, root_q, root_t).vertices
    body = body_frame(verts, root_q, root_t)
    ground = ground_height(lowest_heights(body.detach())) + 0.05  # some vertices below it
    loss = sinking_loss(body, ground, SIZE) + foot_sliding_loss(body, ground, SIZE)
    (grad_rot,) = torch.autograd.grad(loss, rot, retain_graph=True)
    assert loss.item() > 0 and grad_rot.abs().sum() > 0
    acc = vertex_acceleration_loss(verts, SIZE)
    grads = torch.autograd.grad(acc, (rot, root_q, root_t))
    assert all(gr.abs().sum() > 0 for gr in grads)


def test_a_fit_computes_the_terms_only_when_weighted(tmp_path):
    from zooctl.benchdata.make import make_video
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.run import fit_video

    on = {"ground_contact": 1.0, "smooth_3d": 1.0, "edge_stretch": 1.0, "gait_symmetry": 1.0}
    tiny = tiny_overrides(3) | {"weights": on}
    cfg = FitConfig.from_dict(json.loads(json.dumps(tiny)))
    assert cfg.to_dict()["weights"]["ground_contact"] == 1.0
    asset = tube_asset(bones=3, name="tube")
    video = load_fit_video(make_video(asset, tmp_path / "v", frames=4, size=32, seed=0))
    res = fit_video(video, asset, cfg)
    hist = res.history["stage2"]
    assert all("ground" in s and "smooth_3d" in s and s["edge_stretch"] >= 0 for s in hist)
    assert all(math.isfinite(s["ground"]) and s["smooth_3d"] >= 0 for s in hist)
    assert all(math.isfinite(s["gait"]) and s["gait"] >= 0 for s in hist)  # the tube's ends mirror
    off = fit_video(
        video, asset, FitConfig.from_dict(tiny_overrides(3) | {"weights": dict.fromkeys(on, 0.0)})
    )
    assert all(not {"ground", "smooth_3d", "edge_stretch", "gait"} & set(s) for s in off.history["stage2"])
    defaults = FitConfig().weights
    assert defaults.ground_contact == 0.0 and defaults.smooth_3d == 0.0  # measured, not adopted
    assert defaults.gait_symmetry == 0.0
    assert defaults.edge_stretch == 0.5  # adopted, chosen leave-one-video-out (BENCHMARKS.md)
    assert FitConfig().ablation.share_seams  # adopted with it: no crack along the seams


def test_mesh_edges_are_each_undirected_edge_once():
    faces = torch.tensor([[0, 1, 2], [2, 1, 3]])
    assert mesh_edges(faces).tolist() == [[0, 1], [0, 2], [1, 2], [1, 3], [2, 3]]


def test_a_rigid_move_costs_no_stretch_and_a_torn_surface_costs_the_log_of_its_stretch():
    from zooctl.rig.rotations import quat_to_matrix

    asset = tube_asset(bones=3, name="tube")
    rest = torch.as_tensor(asset.vertices, dtype=torch.float32)
    edges = mesh_edges(torch.as_tensor(asset.faces, dtype=torch.long))
    R = quat_to_matrix(torch.tensor([math.cos(0.4), 0.0, math.sin(0.4), 0.0]))
    moved = (rest @ R.T + torch.tensor([0.3, -1.0, 2.0]))[None]
    assert edge_stretch_loss(moved, rest, edges) < 1e-10
    doubled = 2.0 * rest[None]
    assert edge_stretch_loss(doubled, rest, edges) == pytest.approx(math.log(2.0 / 1.5) ** 2, rel=1e-5)
    assert edge_stretch_loss(1.4 * rest[None], rest, edges) == 0.0  # within what bending does
    torn = rest.clone()
    torn[0] += 5.0  # one vertex dragged away: only its edges stretch
    per_edge = edge_log_stretch(torn, rest, edges)
    touching = (edges == 0).any(1)
    assert (per_edge[touching] > 1.0).all() and per_edge[~touching].abs().max() < 1e-6


def test_the_log_stretch_from_squared_lengths_equals_the_ratio_of_lengths():
    """Half the log of the squared lengths' ratio (no square roots) is the log of the lengths'
    ratio, gradients too, for a batch of posed copies against a rest shape that learns."""
    torch.manual_seed(0)
    asset = tube_asset(bones=3, name="tube")
    rest = torch.as_tensor(asset.vertices, dtype=torch.float64).requires_grad_()
    verts = (rest.detach() + 0.05 * torch.randn(4, *rest.shape, dtype=torch.float64)).requires_grad_()
    edges = mesh_edges(torch.as_tensor(asset.faces, dtype=torch.long))

    def length(v):
        return (v[..., edges[:, 0], :] - v[..., edges[:, 1], :]).norm(dim=-1)

    want = torch.log(length(verts) / length(rest))
    got = edge_log_stretch(verts, rest, edges)
    torch.testing.assert_close(got, want, rtol=1e-12, atol=1e-12)
    w = torch.randn_like(want)
    for a, b in zip(
        torch.autograd.grad((got * w).sum(), (verts, rest)),
        torch.autograd.grad((want * w).sum(), (verts, rest)),
    ):
        torch.testing.assert_close(a, b, rtol=1e-10, atol=1e-10)


def test_the_stretch_gradient_reaches_the_skinning_weights():
    """Bent at its joints, a tube's skinning decides how its edges stretch: the term pulls on
    the skinning logits (what it is there to hold) as well as on the rotations."""
    from zooctl.rig.model import ArticulatedModel

    model = ArticulatedModel(tube_asset(bones=3, name="tube"))
    g = torch.Generator().manual_seed(0)
    rot = (model.rest_rotation.detach() + 1.5 * torch.randn(model.rest_rotation.shape, generator=g))[None]
    rot.requires_grad_(True)
    edges = mesh_edges(model.faces)
    with torch.no_grad():
        rest = model().vertices
    loss = edge_stretch_loss(model(rot).vertices, rest, edges)
    grad_rot, grad_skin = torch.autograd.grad(loss, (rot, model.skin.logits))
    assert loss.item() > 0 and grad_rot.abs().sum() > 0 and grad_skin.abs().sum() > 0


def _legs(front: float) -> torch.Tensor:
    """(40, 2, 3) a left (x = -1) and a right (x = +1) foot swinging along z over one cycle,
    half a cycle apart, around ``front`` (left) and ``-front`` (right)."""
    t = torch.linspace(0.0, 2.0 * math.pi, 41, dtype=torch.float64)[:-1]
    left = torch.stack((-torch.ones_like(t), torch.zeros_like(t), front + 0.3 * torch.sin(t)), -1)
    right = torch.stack((torch.ones_like(t), torch.zeros_like(t), -front + 0.3 * torch.sin(t + math.pi)), -1)
    return torch.stack((left, right), 1)


def test_a_mirrored_gait_costs_nothing_and_a_leg_kept_in_front_costs_its_offset():
    pairs, normal = torch.tensor([[0, 1]]), torch.tensor([1.0, 0.0, 0.0], dtype=torch.float64)
    assert gait_symmetry_loss(_legs(0.0), pairs, normal, 0.0, SIZE).item() < 1e-12
    kept = gait_symmetry_loss(_legs(0.5), pairs, normal, 0.0, SIZE)
    assert kept.item() == pytest.approx((1.0 / SIZE) ** 2, rel=1e-6)  # the means 1.0 apart along z
    stiff = _legs(0.0)
    stiff[:, 0, 2] = stiff[:, 0, 2].mean()  # the left leg held still: the spreads differ
    assert gait_symmetry_loss(stiff, pairs, normal, 0.0, SIZE).item() > 0.01
    assert gait_symmetry_loss(_legs(0.5), pairs[:0], normal, 0.0, SIZE).item() == 0.0


def test_the_gait_gradient_reaches_both_legs_and_is_finite_for_a_still_pair():
    joints = _legs(0.5).requires_grad_(True)
    pairs, normal = torch.tensor([[0, 1]]), torch.tensor([1.0, 0.0, 0.0], dtype=torch.float64)
    (grad,) = torch.autograd.grad(gait_symmetry_loss(joints, pairs, normal, 0.0, SIZE), joints)
    assert grad[:, 0].abs().sum() > 0 and grad[:, 1].abs().sum() > 0
    still = torch.zeros(5, 2, 3, dtype=torch.float64, requires_grad=True)
    (grad,) = torch.autograd.grad(gait_symmetry_loss(still, pairs, normal, 0.5, SIZE), still)
    assert torch.isfinite(grad).all()


def test_a_quadrupeds_mirrored_joints_reflect_onto_each_other():
    from zooctl.procedural import build_animal
    from zooctl.rig.model import ArticulatedModel
    from zooctl.rig.priors import reflect

    model = ArticulatedModel(build_animal("quadruped"))
    normal, offset, pairs = model.mirrored_joints()
    assert len(pairs) >= 4  # at least the four legs' joints
    heads = model(None).joints.detach()
    gap = (reflect(heads[pairs[:, 0]], normal, offset) - heads[pairs[:, 1]]).norm(dim=-1)
    assert gap.max() < 0.02 * model.points.max(0).values.sub(model.points.min(0).values).norm()


def test_an_articulation_plugin_gets_only_the_options_its_factory_names(monkeypatch):
    """A plugin written before an option existed ignores it instead of failing."""
    import dataclasses

    from zooctl.plugins import get_registry
    from zooctl.rig.base import get_articulation_model
    from zooctl.rig.model import ArticulatedModel

    seen = {}

    def old_factory(asset, device="cpu", stretch=True):
        seen["stretch"] = stretch
        return ArticulatedModel(asset, device=device, stretch=stretch)

    def new_factory(asset, device="cpu", **options):
        seen.update(options)
        return ArticulatedModel(asset, device=device, **options)

    reg = get_registry()
    spec = reg.get("articulation_model", "casa")
    asset = tube_asset(bones=3, name="tube")
    for factory in (old_factory, new_factory):
        monkeypatch.setitem(
            reg.components["articulation_model"], "casa", dataclasses.replace(spec, factory=factory)
        )
        seen.clear()
        model = get_articulation_model("casa", asset, stretch=False, share_seams=True)
        assert seen["stretch"] is False and model.num_joints == asset.num_joints
        assert ("share_seams" in seen) == (factory is new_factory)
