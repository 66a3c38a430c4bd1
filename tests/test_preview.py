"""The CPU preview renderer (z-buffer, Lambert), contact sheets and `zooctl bank render`."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from cli_helpers import run_inprocess, zooctl
from PIL import Image

from zooctl.errors import InputError
from zooctl.io.video import probe_codec
from zooctl.procedural import build_animal
from zooctl.render.preview import (
    PreviewRenderer,
    contact_sheet,
    fit_camera,
    orbit_camera,
    render_asset,
    render_asset_frames,
    zbuffer_mesh,
)


def quad(z: float, half: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A square facing +Z at depth z (two triangles, counter-clockwise seen from +Z)."""
    v = np.array([[-half, -half, z], [half, -half, z], [half, half, z], [-half, half, z]], dtype=np.float32)
    return v, np.array([[0, 1, 2], [0, 2, 3]])


def test_rasterizer_covers_the_projected_square_and_keeps_the_nearest():
    cam = orbit_camera(np.array([0.0, 0.0, 10.0]), np.zeros(3), 64, 64, fov_y=30.0)
    far_v, far_f = quad(0.0, 2.0)
    near_v, near_f = quad(1.0, 0.5)
    v = torch.tensor(np.concatenate([far_v, near_v]))
    f = torch.tensor(np.concatenate([far_f, near_f + 4]))
    xy, z = cam.project(v[None])
    ids, bary = zbuffer_mesh(xy[0], z[0], f, 64, 64)
    # Expected footprint of the far square: half-width 2 at distance 10, focal 32 / tan(15 deg).
    focal = 32 / np.tan(np.radians(15))
    half_px = 2 * focal / 10
    covered = (ids >= 0).sum().item()
    assert covered == pytest.approx((2 * half_px) ** 2, rel=0.08)
    centre = ids[32, 32].item()
    assert centre in (2, 3)  # the near square's faces win the z-test at the centre
    assert ids[32, 32 + int(half_px) - 2].item() in (0, 1)  # outside the near square: the far one
    assert ids[0, 0].item() == -1
    w = bary[ids >= 0]
    np.testing.assert_allclose(w.sum(-1).numpy(), 1.0, atol=1e-5)
    assert (w >= -1e-4).all()


def test_lambert_shading_and_colours():
    cam = orbit_camera(np.array([0.0, 0.0, 5.0]), np.zeros(3), 32, 32)
    v, f = quad(0.0, 0.8)
    red = np.tile([1.0, 0.0, 0.0], (4, 1))
    lit = PreviewRenderer(light=(0, 0, 1)).render(v, f, cam, red)
    grazing = PreviewRenderer(light=(1, 0, 0.05)).render(v, f, cam, red)
    c = lit[16, 16]
    assert c[0] > 240 and c[1] < 5 and c[2] < 5  # full red, facing the light
    assert grazing[16, 16, 0] < c[0] - 40  # lit from the side: darker
    bg = lit[0, 0]
    assert abs(int(bg[0]) - int(bg[2])) < 30 and bg[0] > 150  # the grey background


def test_render_asset_frames_a_moving_clip():
    a = build_animal("fish")
    frames = render_asset(a, "swim", [0, 7], size=64, supersample=1)
    assert frames.shape == (2, 64, 64, 3) and frames.dtype == np.uint8
    assert np.abs(frames[0].astype(int) - frames[1]).max() > 30  # the fish moved
    bg = frames[0, :, :1].astype(int)  # the background is a vertical gradient: compare per row
    fg = np.abs(frames[0].astype(int) - bg).sum(-1) > 40
    ys, xs = np.nonzero(fg)
    assert fg.mean() > 0.1 and xs.min() > 0 and xs.max() < 63  # in frame, not cropped
    with pytest.raises(InputError, match="no clip 'fly'"):
        render_asset(a, "fly")


def test_a_clip_renders_a_few_frames_at_a_time_as_it_renders_whole():
    """`bank render --video` writes frames as they are rendered: posed and drawn in small batches,
    the camera framing the whole clip all the same."""
    a = build_animal("fish")
    whole = render_asset(a, "swim", range(9), size=48, supersample=1, batch=9)
    stream = render_asset_frames(a, "swim", range(9), size=48, supersample=1, batch=2)
    assert not isinstance(stream, np.ndarray)
    assert np.array_equal(np.stack(list(stream)), whole)


def test_fit_camera_rejects_nothing_to_frame():
    with pytest.raises(InputError):
        fit_camera(np.zeros((0, 3)), 10, 10)
    with pytest.raises(InputError, match="faces"):
        PreviewRenderer().render(
            np.zeros((3, 3)), np.array([[0, 1, 5]]), orbit_camera(np.array([0, 0, 5.0]), np.zeros(3), 8, 8)
        )


def test_contact_sheet_layout():
    tiles = [np.full((20, 30, 3), i * 40, np.uint8) for i in range(5)]
    sheet = contact_sheet(tiles, [f"t{i}" for i in range(5)], columns=3, pad=2, label_height=10)
    assert sheet.shape == (2 * (20 + 10 + 2) + 2, 3 * (30 + 2) + 2, 3)
    assert (sheet[2:22, 2 + 32 : 32 + 32] == 40).all()  # tile 1 in row 0, column 1


def test_cli_render_still_video_and_sheet(store, tmp_path, capsys):
    assert zooctl("bank", "seed", "--plan", "fish", "--plan", "bird", "--no-variants").code == 0
    png = tmp_path / "bird.png"
    r = run_inprocess(
        capsys, "bank", "render", "bird", "--clip", "flap", "--frame", "3", "--size", "96", "-o", str(png)
    )
    assert r.code == 0, r.err
    assert Image.open(png).size == (96, 96)
    mp4 = tmp_path / "fish.mp4"
    r = zooctl("bank", "render", "fish", "--clip", "swim", "--size", "64", "-o", str(mp4))
    assert r.code == 0, r.err
    assert probe_codec(mp4) == "h264"
    sheet = tmp_path / "bank.png"
    r = run_inprocess(capsys, "bank", "render", "--sheet", "--size", "64", "-o", str(sheet), "--json")
    assert r.code == 0, r.err
    assert r.json()["assets"] == ["bird", "fish"]
    assert Image.open(sheet).size[0] > 2 * 64
    for args, msg in (
        (("render", "nope", "-o", str(png)), "no asset named 'nope'"),
        (("render", "fish", "-o", str(tmp_path / "x.gif")), "cannot render to 'x.gif'"),
        (("render", "fish", "--clip", "swim", "--frame", "99", "-o", str(png)), "outside clip 'swim'"),
        (("render", "--sheet", "-o", str(tmp_path / "x.mp4")), "contact sheet is a .png"),
    ):
        r = run_inprocess(capsys, "bank", *args)
        assert r.code == 2 and msg in r.err and "Traceback" not in r.err, (args, r.err)


def test_batched_rasterisation_equals_one_image_at_a_time(monkeypatch):
    """A batch of poses is one pass with each image's own depth range: the same face ids and
    weights as rasterising the images one by one, also when the batch is split to keep face ids
    below the packed key's limit."""
    import zooctl.render.preview as P

    cam = orbit_camera(np.array([0.0, 0.0, 10.0]), np.zeros(3), 48, 40, fov_y=30.0)
    far_v, far_f = quad(0.0, 2.0)
    near_v, near_f = quad(1.0, 0.5)
    v = torch.tensor(np.concatenate([far_v, near_v]))
    f = torch.tensor(np.concatenate([far_f, near_f + 4]))
    rng = np.random.default_rng(0)
    # Five poses: shifted, scaled in depth, one partly outside the image, one behind the camera.
    poses = [v + torch.tensor(rng.normal(0, 0.6, 3), dtype=torch.float32) for _ in range(3)]
    poses += [v + torch.tensor([3.0, 0.0, 0.0]), v + torch.tensor([0.0, 0.0, 20.0])]
    xy, z = cam.expand(len(poses)).project(torch.stack(poses))
    skip = torch.tensor(rng.random((len(poses), len(f))) < 0.2)
    one = [zbuffer_mesh(xy[b], z[b], f, 48, 40, skip=skip[b]) for b in range(len(poses))]
    for bits in (P._FACE_BITS, 4):  # 4 bits: 16 face ids, so 5 poses x 4 faces are split
        monkeypatch.setattr(P, "_FACE_BITS", bits)
        ids, bary = zbuffer_mesh(xy, z, f, 48, 40, skip=skip)
        assert ids.shape == (5, 48, 40) and bary.shape == (5, 48, 40, 3)
        for b, (ids1, bary1) in enumerate(one):
            assert torch.equal(ids[b], ids1)
            assert torch.equal(bary[b], bary1)
    assert (one[0][0] >= 0).any() and not (one[4][0] >= 0).any()  # behind the camera: nothing drawn


def test_render_in_bounded_passes_equals_one_pass(monkeypatch):
    import zooctl.render.preview as P

    a = build_animal("fish")
    clip = next(iter(a.clips))
    whole = render_asset(a, clip, range(5), size=40)
    monkeypatch.setattr(P, "_BATCH_PIXELS", 2 * (40 * 2) ** 2)  # two frames per pass at supersample 2
    assert np.array_equal(render_asset(a, clip, range(5), size=40), whole)
