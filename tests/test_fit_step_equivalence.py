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


def test_pose_with_rest_is_the_pose_and_the_rest_shape_of_one_pass():
    """The edge-stretch term's reference posed beside the window's frames equals the model's own
    rest shape (stretched bones, girth and displacement field as they are), and the frames' poses
    equal `pose`'s, values and gradients."""
    from zooctl.fit.scene import FitScene
    from zooctl.procedural import build_animal

    torch.manual_seed(0)
    scene = FitScene(build_animal("quadruped", seed=1), 6, 32, 32, 40.0, hidden=16, girth=True)
    with torch.no_grad():  # a shape and poses away from the template's, as mid-fit
        scene.model.log_bone_scales.add_(0.2 * torch.randn_like(scene.model.log_bone_scales))
        scene.rotations.add_(0.2 * torch.randn_like(scene.rotations))
        scene.root_rotation.add_(0.3 * torch.randn_like(scene.root_rotation))
        scene.root_translation.add_(torch.randn_like(scene.root_translation))
        for p in scene.model.displacement.parameters():
            p.add_(0.1 * torch.randn_like(p))
    frames = torch.tensor([1, 2, 3, 4])
    posed, rest = scene.pose_with_rest(frames)
    want = scene.pose(frames)
    with torch.no_grad():
        want_rest = scene.model().vertices
    torch.testing.assert_close(posed.vertices, want.vertices, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(posed.joints, want.joints, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(rest, want_rest, rtol=1e-5, atol=1e-5)
    assert not rest.requires_grad
    w = torch.randn_like(want.vertices)
    params = [scene.rotations, scene.root_rotation, scene.model.log_bone_scales]
    got_g = torch.autograd.grad((posed.vertices * w).sum(), params)
    want_g = torch.autograd.grad((want.vertices * w).sum(), params)
    for a, b in zip(got_g, want_g, strict=True):
        torch.testing.assert_close(a, b, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("budget", [False, True], ids=["counted", "budgeted"])
def test_a_device_step_reads_back_only_the_pair_counts_or_nothing_with_a_pair_budget(budget):
    """A stage-2 step on the path a GPU runs (the CPU kernels off) makes the host wait for the
    device only where the soft and hard rasterisers count their (face, pixel) pairs: no scalar
    read, boolean mask or ``nonzero`` elsewhere in the forward, backward or optimiser step. With
    ``pair_budget`` not even there: the pairs come from budgets (`PairBudget`) set by the first
    step's count, and each budget reads its calls' counts back after 4, 8 and every 16 steps."""
    import numpy as np
    from torch.utils._python_dispatch import TorchDispatchMode

    from zooctl.fit.config import preset
    from zooctl.fit.losses import MaskTargets
    from zooctl.fit.scene import FitScene
    from zooctl.fit.stages import StageRunner, Targets, make_optimizer
    from zooctl.render import _kernels
    from zooctl.rig.synthetic import tube_asset

    T = 6
    torch.manual_seed(0)
    scene = FitScene(tube_asset(bones=3, rings_per_bone=2, segments=8), T, 24, 24, focal=30.0, hidden=8)
    with torch.no_grad():
        scene.root_translation[:, 2] = -2.0
    masks = np.zeros((T, 24, 24), np.float32)
    masks[:, 6:18, 4:20] = 1.0
    flow = torch.zeros(T - 1, 24, 24, 2)
    targets = Targets(MaskTargets.build(masks, seed=0), flow, torch.ones(T - 1, 24, 24, dtype=torch.bool))
    cfg = preset("fast")
    cfg.stage2.batch = 4
    cfg.pair_budget = budget
    runner = StageRunner(scene, targets, cfg, 2)
    opt = make_optimizer(scene, cfg, 2, learn_focal=False)
    reads = []

    class Reads(TorchDispatchMode):
        def __torch_dispatch__(self, func, types, args=(), kwargs=None):
            name = func.overloadpacket.__name__
            index_by_mask = name == "index" and any(
                isinstance(i, torch.Tensor) and i.dtype == torch.bool
                for i in (args[1] or ())
                if i is not None
            )
            syncs = ("_local_scalar_dense", "nonzero", "masked_select", "unique", "_unique2")
            if (name in syncs or index_by_mask) and not in_adam:
                reads.append(name)
            return func(*args, **(kwargs or {}))

    in_adam = False  # Adam reads its step counts, which stay on the host whatever the device
    adam_step = opt.step

    def step(*a, **k):
        nonlocal in_adam
        in_adam = True
        try:
            return adam_step(*a, **k)
        finally:
            in_adam = False

    opt.step = step
    per_step = []
    with _kernels.disabled():
        runner.step(opt, 0)  # Adam's state made, the pair budgets set
        for it in range(1, 29):  # the budgets read back after 4, 8 and 16 steps
            with Reads():
                terms = runner.step(opt, it)
            per_step.append(reads)
            reads = []
    assert "flow" in terms and "edge_stretch" in terms
    if not budget:
        assert per_step == [["_local_scalar_dense"] * 2] * 28, per_step
        assert runner.pair_overflows() == 0 and runner.silhouette.budget.reads == 0
        return
    assert per_step == [[]] * 28, [(i, r) for i, r in enumerate(per_step) if r]
    for b in (runner.silhouette.budget, runner.flow_renderer.budget):
        assert b.reads == 4 and b.overflows == 0  # the first count, then after 4, 8, 16
    assert runner.pair_overflows() == 0
    runner.silhouette.budget.capacity = 64  # far too small: the next step's silhouettes lose pixels
    with _kernels.disabled():
        runner.step(opt, 29)
    assert runner.pair_overflows() == 1  # read back at the stage's end, as a fit does
