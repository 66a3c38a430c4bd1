"""The fit's loss terms and step schedule: contour term beyond the crop, epoch windows, lr decay,
the smoothness weight's decay."""

import numpy as np
import pytest
import torch

from zooctl.fit.losses import MaskTargets, contour_loss, nearest_points
from zooctl.fit.run import lr_factor
from zooctl.render import _kernels


def _square_targets(T: int = 1, h: int = 32, w: int = 32) -> MaskTargets:
    cov = np.zeros((T, h, w), np.float32)
    cov[:, 8:24, 8:24] = 1.0
    return MaskTargets.build(cov, num_samples=64)


def test_contour_pulls_vertices_back_from_beyond_the_image():
    """A vertex outside the fit image (where the distance transform is clamped) still gets a
    gradient towards the mask, and a farther one costs more."""
    mt = _square_targets()
    frames = torch.zeros(1, dtype=torch.long)
    weight = torch.ones(1)
    inside = torch.tensor([[[16.0, 16.0]] * 8])
    losses = []
    for x in (40.0, 60.0):
        xy = inside.clone()
        xy[0, 0] = torch.tensor([x, 16.0])
        xy.requires_grad_(True)
        loss = contour_loss(xy, frames, mt, weight)
        loss.backward()
        assert xy.grad[0, 0, 0] > 0  # descending the gradient moves it left, back into the image
        losses.append(loss.item())
    assert losses[1] > losses[0]


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_nearest_points_is_the_first_nearest(dtype):
    """Kernel (CPU) and PyTorch path (CUDA's) against float64 brute force: sizes off the kernel's
    vector lanes (2 to 16) and 64-query blocks, exact ties in other lanes and in the same lane (the
    first index wins), a NaN point (never nearest)."""
    g = torch.Generator().manual_seed(3)
    pts = (torch.rand(3, 37, 2, generator=g, dtype=torch.float64) * 40).to(dtype)
    pts[:, 20] = pts[:, 5]  # a duplicate of an earlier point: the tie goes to index 5
    pts[:, 21] = pts[:, 5]  # another, in index 5's lane for 2, 4, 8 or 16 lanes
    pts[1, 7] = float("nan")
    q = (torch.rand(3, 70, 2, generator=g, dtype=torch.float64) * 40).to(dtype)
    q[:, 0] = pts[:, 20]  # exactly on the duplicated point
    d = torch.cdist(q.double(), torch.nan_to_num(pts.double(), nan=1e9))
    truth = d.argmin(-1)
    got = nearest_points(q, pts)
    assert got.dtype == torch.long and got.shape == (3, 70)
    assert torch.equal(got, truth) and (got[:, 0] == 5).all()
    if _kernels.available():
        clean = [0, 2]  # the PyTorch path's min() would return the NaN
        with _kernels.disabled():
            fallback = nearest_points(q[clean], pts[clean])
        # The expansion |x|^2 - 2 q.x rounds: it may pick another point only in a near-tie.
        picked = d[clean].gather(-1, fallback[..., None])[..., 0]
        assert (picked - d[clean].min(-1).values).max() <= 1e-3


def test_stage2_windows_cover_every_frame_each_epoch():
    from zooctl.fit.stages import StageRunner

    T, B = 23, 5
    present = np.ones(T, bool)
    present[10:15] = False  # one window's worth of empty masks
    runner = StageRunner.__new__(StageRunner)
    runner.gen = np.random.default_rng(0)
    runner.present_idx, runner.steps_from = np.nonzero(present)[0], 0
    for _ in range(5):
        starts = runner._epoch_windows(T, B)
        seen = np.zeros(T, int)
        for s in starts:
            assert 0 <= s <= T - B
            seen[s : s + B] += 1
        assert (seen[present] >= 1).all()
        assert all(present[s : s + B].any() for s in starts)


@pytest.mark.parametrize("final", [0.05, 0.5])
def test_lr_factor_decays_from_one_to_final(final):
    f = [lr_factor(i, 50, final) for i in range(50)]
    assert f[0] == pytest.approx(1.0) and f[-1] == pytest.approx(final)
    assert all(a >= b for a, b in zip(f, f[1:]))
    assert lr_factor(3, 50, 1.0) == 1.0


def test_smooth_weight_decays_from_start_to_smooth():
    from zooctl.fit.config import LossWeights
    from zooctl.fit.stages import smooth_weight

    w = LossWeights(smooth=10.0, smooth_start=1000.0, smooth_until=0.5)
    f = [smooth_weight(w, i, 100) for i in range(100)]
    assert f[0] == pytest.approx(1000.0) and f[25] == pytest.approx(100.0)
    assert all(v == pytest.approx(10.0) for v in f[50:])
    assert all(a > b for a, b in zip(f[:50], f[1:51]))
    assert smooth_weight(LossWeights(smooth=10.0), 0, 100) == 10.0  # the default: constant
    assert smooth_weight(LossWeights(smooth=0.0, smooth_start=1000.0), 3, 100) == 0.0  # term off


def test_smooth_until_is_checked():
    from zooctl.errors import UsageError
    from zooctl.fit.config import FitConfig

    with pytest.raises(UsageError, match="smooth_until"):
        FitConfig.from_dict({"weights": {"smooth_start": 100.0, "smooth_until": 0}})
