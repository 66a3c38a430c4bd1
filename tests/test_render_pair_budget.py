"""Pairs of a fixed capacity (`zooctl.render.windows.PairBudget`, `FitConfig.pair_budget`): the
device path's renderers read nothing back a call, and render what the counted pairs render."""

import pytest
import torch

from zooctl.render import _kernels
from zooctl.render.camera import look_at
from zooctl.render.raster import RasterFlow, rasterize
from zooctl.render.soft import SoftSilhouette
from zooctl.render.windows import PairBudget, face_pixel_pairs, project_faces
from zooctl.rig.synthetic import uv_sphere

pytestmark = pytest.mark.usefixtures("one_thread")  # see conftest


def _scene():
    v, f = uv_sphere(600)
    v = torch.as_tensor(v, dtype=torch.float32)
    verts = torch.stack((v, v * torch.tensor([1.3, 0.8, 1.0]))) + torch.tensor([0.3, 0.0, 0.0])
    cam = look_at([[0.0, 0.3, 3.5], [2.0, 1.0, 2.5]], [0.2, 0.0, 0.0], 40, 48)
    return verts, torch.as_tensor(f), cam


def test_pairs_of_a_capacity_are_the_counted_pairs_then_padding():
    verts, faces, cam = _scene()
    sf = project_faces(verts, faces, cam)
    exact = face_pixel_pairs(sf, 40, 48, 1.5)
    n, P = 2 * 40 * 48, len(exact.face)
    big = face_pixel_pairs(sf, 40, 48, 1.5, capacity=P + 100)
    assert int(big.total) == P and len(big.face) == P + 100
    for a, b in ((exact.face, big.face), (exact.pixel, big.pixel), (exact.px, big.px), (exact.py, big.py)):
        assert torch.equal(a, b[:P])
    assert (big.pixel[P:] == n).all() and (
        big.face[P:] == 2 * sf.num_faces
    ).all()  # padding: one past the last
    small = face_pixel_pairs(sf, 40, 48, 1.5, capacity=P - 50)  # too few: the first ones, counted in full
    assert int(small.total) == P and torch.equal(small.pixel, exact.pixel[: P - 50])


def _render(renderer, verts, faces, cam):
    if isinstance(renderer, RasterFlow):
        return renderer(verts, faces, cam, verts * 1.01)["flow"]
    return renderer(verts, faces, cam)


def _budgeted(renderer):
    renderer.budget.on = True
    return renderer


@pytest.mark.parametrize(
    "make", [lambda: SoftSilhouette((40, 48), sigma=0.5), RasterFlow], ids=["soft", "flow"]
)
def test_a_budgeted_renderer_renders_what_the_counted_pairs_render(make):
    verts, faces, cam = _scene()
    verts = verts.requires_grad_(True)
    assert not make().budget.on  # off by default (`FitConfig.pair_budget`)
    budgeted = _budgeted(make())
    with _kernels.disabled():
        _render(budgeted, verts, faces, cam)  # the first call counts its pairs and sets the budget
        assert budgeted.budget.capacity is not None and budgeted.budget.reads == 1
        got = _render(budgeted, verts, faces, cam)
        want = _render(make(), verts, faces, cam)  # a renderer's first call: the pairs counted
    assert budgeted.budget.reads == 1  # the budgeted call read nothing back
    torch.testing.assert_close(got, want, rtol=0, atol=1e-6)
    grads = [torch.autograd.grad(o.square().sum(), verts)[0] for o in (got, want)]
    torch.testing.assert_close(grads[0], grads[1], rtol=1e-5, atol=1e-6)


def test_a_budget_too_small_leaves_pairs_out_counts_them_and_grows():
    verts, faces, cam = _scene()
    budget = PairBudget()
    budget.on = True
    with _kernels.disabled():
        first = rasterize(verts, faces, cam, budget).mask  # counted: sets the budget
        assert budget.reads == 1 and budget.capacity is not None
        budget.capacity = 4096  # far too small for this body
        small = [rasterize(verts * s, faces, cam, budget).mask for s in (1.0, 1.02, 1.04, 1.06)]
        assert budget.reads == 2 and budget.overflows == 4  # read back after the 4th call
        assert budget.capacity > 4096 and budget.capacity % budget.quantum == 0
        again = rasterize(verts, faces, cam, budget).mask
    assert small[0].sum() < first.sum()  # what was left out is missing from the picture
    assert torch.equal(again, first)  # the grown budget holds every pair


def test_padding_touches_no_face_even_where_the_first_face_is_not_drawable():
    """Padding pairs compute on a row of their own, so a first face with a NaN corner (a vertex
    the fit sent through the camera) gives no NaN gradient, as it gives none counted exactly."""
    verts, faces, cam = _scene()
    verts[0, faces[0, 0]] = float("nan")
    verts.requires_grad_(True)
    budgeted = _budgeted(SoftSilhouette((40, 48), sigma=0.5))
    with _kernels.disabled():
        budgeted(verts, faces, cam)
        got = budgeted(verts, faces, cam)
        want = SoftSilhouette((40, 48), sigma=0.5)(verts, faces, cam)
    assert torch.isfinite(got).all() and torch.equal(got, want)
    (g_got,) = torch.autograd.grad(got.sum(), verts)
    (g_want,) = torch.autograd.grad(want.sum(), verts)
    assert int(torch.isfinite(g_want).sum()) == g_want.numel() - 3  # the NaN vertex's own alone
    torch.testing.assert_close(g_got, g_want, rtol=0, atol=0, equal_nan=True)


def test_a_budget_is_not_used_on_the_cpu_kernels_machine_path():
    """Where the CPU runs the pair path only because no compiler built the kernels, a budget
    counts exactly (a CPU waits for nothing; counting is cheaper than padding)."""
    if not _kernels.enabled():
        pytest.skip("the kernels are turned off in this environment (ZOOCTL_RENDER_KERNELS)")
    verts, faces, cam = _scene()
    budget = PairBudget()
    budget.on = True
    budget.pairs(project_faces(verts, faces, cam), 40, 48, 0.0)
    assert budget.capacity is None and budget.reads == 0
