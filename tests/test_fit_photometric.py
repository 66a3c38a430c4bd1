"""The photometric term (`zooctl.fit.photometric`): the surface in per-vertex colours rendered
through the z-buffer against the frames; what it costs, what the gain absorbs, where its gradient
goes, and that a fit learns the colours only when the term is weighted."""

from __future__ import annotations

import json
import math

import numpy as np
import torch
from fit_helpers import tiny_overrides

from zooctl.fit.config import FitConfig
from zooctl.fit.photometric import colour_targets, initial_colours, photometric_loss
from zooctl.render.camera import Camera
from zooctl.render.raster import interpolate, rasterize
from zooctl.rig.synthetic import tube_asset

H = W = 48


def _scene() -> tuple[torch.Tensor, torch.Tensor, Camera, torch.Tensor]:
    """(1, V, 3) a tube in front of a camera, its faces, the camera, and (V, 3) colours that vary
    along it (red to blue) and around it (green)."""
    asset = tube_asset(bones=3, name="tube")
    v = torch.as_tensor(asset.vertices, dtype=torch.float64) * torch.tensor(
        [1.0, 4.0, 4.0], dtype=torch.float64
    )
    v = v - v.mean(0)
    v = v / v.abs().max() * 0.8
    verts = (v + torch.tensor([0.0, 0.0, 3.0], dtype=torch.float64))[None]
    faces = torch.as_tensor(asset.faces, dtype=torch.long)
    k = torch.tensor([[80.0, 80.0, W / 2, H / 2]], dtype=torch.float64)
    cam = Camera(k, torch.eye(3, dtype=torch.float64)[None], torch.zeros(1, 3, dtype=torch.float64), H, W)
    a = (v[:, 0] - v[:, 0].min()) / (v[:, 0].max() - v[:, 0].min())
    colours = torch.stack((1 - a, 0.5 + 0.4 * torch.sign(v[:, 1]) * v[:, 1].abs().sqrt(), a), -1).clamp(0, 1)
    return verts, faces, cam, colours


def _frame(verts, faces, cam, colours) -> tuple[torch.Tensor, torch.Tensor]:
    """(1, H, W, 3) the surface rendered in its colours and (1, H, W) its mask, as a video would show it."""
    frags = rasterize(verts, faces, cam)
    return interpolate(colours[None], faces, frags).detach(), frags.mask.to(verts.dtype)


def test_the_surface_in_its_own_colours_costs_nothing_even_under_another_exposure():
    verts, faces, cam, colours = _scene()
    image, mask = _frame(verts, faces, cam, colours)
    assert mask.sum() > 100
    assert photometric_loss(verts, faces, cam, colours, image, mask).item() < 1e-9
    brighter = image * torch.tensor([1.4, 1.2, 0.8], dtype=image.dtype)  # a per-channel gain
    assert photometric_loss(verts, faces, cam, colours, brighter, mask).item() < 1e-9
    grey = torch.full_like(colours, 0.5)
    assert photometric_loss(verts, faces, cam, grey, image, mask).item() > 0.05


def test_the_gradient_moves_a_shifted_surface_back_where_its_colours_are_seen():
    verts, faces, cam, colours = _scene()
    image, mask = _frame(verts, faces, cam, colours)
    valid = torch.ones_like(mask)  # every covered pixel counts: no mask to pull it back
    shift = torch.tensor([0.06, 0.0, 0.0], dtype=verts.dtype)
    moved = (verts + shift).requires_grad_(True)
    loss = photometric_loss(moved, faces, cam, colours, image, valid)
    (g,) = torch.autograd.grad(loss, moved)
    assert loss.item() > 0.01
    assert g[..., 0].sum() > 0  # descending moves it back along -x
    step = moved.detach() - 0.02 * g / g.abs().max()
    assert photometric_loss(step, faces, cam, colours, image, valid).item() < loss.item()


def test_the_gradient_reaches_the_colours_and_only_through_covered_masked_pixels():
    verts, faces, cam, colours = _scene()
    image, mask = _frame(verts, faces, cam, colours)
    learned = torch.full_like(colours, 0.5).requires_grad_(True)
    loss = photometric_loss(verts, faces, cam, learned, image, mask)
    (g,) = torch.autograd.grad(loss, learned)
    assert g.abs().sum() > 0
    none = photometric_loss(verts, faces, cam, learned, image, torch.zeros_like(mask))
    assert none.item() == 0.0


def test_colour_targets_crop_and_resize_the_frames():
    frames = np.zeros((2, 40, 60, 3), np.uint8)
    frames[:, 10:30, 20:40] = (255, 0, 128)
    out = colour_targets(frames, (20, 10, 40, 30), 8, 8)
    assert out.shape == (2, 8, 8, 3) and out.dtype == torch.float32
    assert torch.allclose(out[0, 4, 4], torch.tensor([1.0, 0.0, 128 / 255]))


def _cfg(weight: float, iters: int = 3) -> FitConfig:
    return FitConfig.from_dict(
        json.loads(json.dumps(tiny_overrides(iters) | {"weights": {"photometric": weight}}))
    )


def _video(tmp_path):
    from zooctl.benchdata.make import make_video
    from zooctl.fit.inputs import load_fit_video

    asset = tube_asset(bones=3, name="tube")
    return load_fit_video(make_video(asset, tmp_path / "v", frames=4, size=32, seed=0)), asset


def _fit(tmp_path, weight: float):
    from zooctl.fit.run import fit_video

    video, asset = _video(tmp_path)
    return fit_video(video, asset, _cfg(weight)), video


def test_a_fit_learns_colours_only_when_the_term_is_weighted(tmp_path):
    res, video = _fit(tmp_path, 1.0)
    hist = res.history["stage2"]
    assert hist and all("photo" in s and math.isfinite(s["photo"]) and s["photo"] >= 0 for s in hist)
    off, _ = _fit(tmp_path / "off", 0.0)
    assert all("photo" not in s for s in off.history["stage2"])
    assert FitConfig().weights.photometric == 0.0  # measured, not adopted (BENCHMARKS.md)


def test_initial_colours_are_what_the_frames_show_at_the_visible_vertices(tmp_path):
    """Started on a frame where each pixel shows a solid colour, every vertex seen inside the mask
    takes it, and the ones never seen take the mean of the seen."""
    from zooctl.fit.run import new_scene

    asset = tube_asset(bones=3, name="tube")
    cfg = FitConfig.from_dict(tiny_overrides(1))
    scene = new_scene(asset, cfg, 2, 32, 32, (16.0, 16.0))
    with torch.no_grad():
        scene.root_translation[:, 0] = -1.5  # the tube (x in [0, 3]) centred,
        scene.root_translation[:, 2] = -9.0  # in front of the camera (it looks down -Z),
        scene.log_focal.fill_(math.log(80.0))  # about 27 px long
    images = torch.zeros(2, 32, 32, 3)
    images[..., 0] = 0.25
    images[..., 2] = 0.75
    coverage = torch.ones(2, 32, 32)
    c = initial_colours(scene, images, coverage, range(2))
    assert c.shape == (asset.vertices.shape[0], 3)
    seen = scene.camera(1).project(scene.pose(torch.arange(1)).vertices)[0][0]
    assert (seen.amax(0) - seen.amin(0)).min() > 2  # on screen, not a point
    assert torch.allclose(c, torch.tensor([0.25, 0.0, 0.75]).expand_as(c))
    images[:, :, :16] = 1.0  # white outside the mask (the left half): no vertex takes it
    coverage[:, :, :16] = 0
    assert torch.allclose(initial_colours(scene, images, coverage, range(2)), c)


def test_a_paused_fit_resumes_with_the_colours_it_had_learned(tmp_path):
    """The template trials pause a fit and the winner's goes on from its state: with the term on,
    it goes on exactly as a fit never paused."""
    from zooctl.fit.run import fit_video

    video, asset = _video(tmp_path)
    straight = fit_video(video, asset, _cfg(1.0, 4))
    paused = fit_video(video, asset, _cfg(1.0, 4), pause_at=2)
    assert paused.paused["colours"].shape == (asset.vertices.shape[0], 3)
    again = fit_video(video, asset, _cfg(1.0, 4), resume=paused.paused)
    assert again.history["stage2"] == straight.history["stage2"]
    a, b = again.scene.state_dict(), straight.scene.state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)
