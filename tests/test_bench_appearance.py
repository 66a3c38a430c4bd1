"""`bench make --appearance textured` (a procedural coat over a natural-looking scene, and what the
held-out cameras see) and the colour error `bench run` reports from those cameras
(`zooctl.benchdata.appearance`), judged with an oracle fit: the true shape and motion."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from zooctl.asset import Clip, RiggedAsset
from zooctl.benchdata.appearance import view_psnr
from zooctl.benchdata.make import KEY_EVERY, make_video, random_motion
from zooctl.geometry import decompose_trs
from zooctl.procedural import build_animal

T, SIZE = 8, 96


@pytest.fixture(scope="module")
def textured(tmp_path_factory):
    asset = build_animal("quadruped", name="quad")
    folder = make_video(
        asset, tmp_path_factory.mktemp("tex"), frames=T, size=SIZE, seed=4, appearance="textured"
    )
    with np.load(folder / "video.npz") as z:
        data = {k: z[k] for k in z.files}
    return asset, folder, data


def test_a_textured_video_has_a_coat_a_scene_and_the_held_out_frames(textured, tmp_path):
    asset, folder, z = textured
    assert json.loads((folder / "meta.json").read_text())["appearance"] == "textured"
    frames, masks, views = z["frames"], z["masks"], z["gt_view_frames"]
    assert views.shape == (2, T, SIZE, SIZE, 3) and views.dtype == np.uint8
    assert not views[~z["gt_view_masks"]].any()  # black around the animal
    assert (views.reshape(-1, 3)[z["gt_view_masks"].reshape(-1)].max(1) > 0).all()
    # The scene is not a flat colour or a smooth gradient: rows vary along themselves.
    bg = frames[0][~masks[0]].astype(np.float64)
    assert bg.std(0).mean() > 12
    row = frames[0, -1].astype(np.float64)
    assert np.abs(np.diff(row, axis=0)).mean() > 1.0
    # The coat is finer than the asset's faces: a face shows more than one colour.
    import torch

    from zooctl.render.camera import Camera
    from zooctl.render.raster import rasterize

    cam = Camera(
        torch.as_tensor(z["intrinsics"][None], dtype=torch.float32),
        torch.as_tensor(z["gt_cam_rotation"][:1], dtype=torch.float32),
        torch.as_tensor(z["gt_cam_translation"][:1], dtype=torch.float32),
        SIZE,
        SIZE,
    )
    fid = rasterize(
        torch.as_tensor(z["gt_vertices"][:1]), torch.as_tensor(asset.faces, dtype=torch.long), cam
    )
    fid = fid.face_ids[0].numpy()
    big = np.bincount(fid[fid >= 0]).argmax()
    assert frames[0][fid == big].std(0).max() > 0  # shading is flat per face: the coat varies
    # A flat video (the default) is what it always was: no held-out frames, no appearance key.
    flat = make_video(asset, tmp_path, frames=3, size=32, seed=4)
    assert "gt_view_frames" not in np.load(flat / "video.npz").files
    assert "appearance" not in json.loads((flat / "meta.json").read_text())


def oracle(asset: RiggedAsset, z: dict) -> RiggedAsset:
    """``asset`` with a ``fit`` clip that poses it, in the fit's camera frame (`CAMERA_ROTATION`
    at the origin), exactly where the video's frames show it: a perfect fit."""
    from zooctl.fit.scene import CAMERA_ROTATION

    local = random_motion(asset, T + KEY_EVERY, np.random.default_rng([4, sum(asset.name.encode())]))[:T]
    M = np.tile(np.eye(4), (T, 1, 1))
    M[:, :3, :3] = CAMERA_ROTATION.T @ z["gt_cam_rotation"]
    M[:, :3, 3] = z["gt_cam_translation"] @ CAMERA_ROTATION  # R_fit^T t
    local = local.copy()
    for j in np.nonzero(np.asarray(asset.parents) < 0)[0]:
        local[:, j] = M @ local[:, j]
    t, q, s = decompose_trs(local)
    out = dataclasses.replace(asset, clips={"fit": Clip("fit", 30.0, q, t, s)})
    posed = out.pose("fit", np.arange(T))
    cam_frame = z["gt_vertices"] @ np.swapaxes(z["gt_cam_rotation"], 1, 2) + z["gt_cam_translation"][:, None]
    assert np.allclose(posed @ CAMERA_ROTATION.T, cam_frame, atol=1e-4 * np.ptp(cam_frame))
    return out


def test_the_colour_error_sees_a_bake_and_not_the_template(textured):
    """The oracle wearing the template's colours (unlit, without the coat), grey, or the coat
    baked from the input frames: from the held-out cameras the bake is clearly closest."""
    import torch

    from zooctl.fit.scene import CAMERA_ROTATION
    from zooctl.fit.texture import bake
    from zooctl.render.camera import Camera

    asset, folder, z = textured
    perfect = oracle(asset, z)
    record = {"frames": T, "metrics": {"frames_evaluated": [0, 3, 7]}}
    cam = Camera(
        torch.as_tensor(z["intrinsics"][None], dtype=torch.float32),
        torch.as_tensor(CAMERA_ROTATION[None], dtype=torch.float32),
        torch.zeros(1, 3),
        SIZE,
        SIZE,
    )
    baked, info = bake(perfect, cam, z["frames"], z["masks"])
    assert info["mode"] == "texture"
    grey = dataclasses.replace(perfect, vertex_colors=np.full_like(asset.vertex_colors, 0.3))
    res = {
        k: view_psnr(a, record, folder) for k, a in (("template", perfect), ("grey", grey), ("baked", baked))
    }
    for r in res.values():
        assert len(r["view_psnr_per_view"]) == 2 and r["psnr_pixels"] > 500
    psnr = {k: r["view_psnr"] for k, r in res.items()}
    assert psnr["baked"] > max(psnr["template"], psnr["grey"]) + 3.0, psnr
    assert res["baked"]["input_psnr"] > 28, res["baked"]  # in sample, true shape: close
    assert res["baked"]["input_psnr"] > res["baked"]["view_psnr"]
    # The contact sheet: truth | render from the input camera and each held-out camera; the
    # oracle's render covers the animal where the held-out truth shows it, grey or not.
    sheet = view_psnr(grey, record, folder, sheet=True)["sheet"]
    assert sheet.shape == (SIZE, 6 * SIZE, 3) and sheet.dtype == np.uint8 and "sheet" not in res["grey"]
    tiles = sheet.reshape(SIZE, 6, SIZE, 3).transpose(1, 0, 2, 3)
    for c in range(3):
        truth, fit = tiles[2 * c].any(-1), tiles[2 * c + 1].any(-1)
        assert fit.sum() > 50 and (fit & truth).sum() > 0.8 * fit.sum()
    assert np.allclose(tiles[3][tiles[3].any(-1)], tiles[3][tiles[3].any(-1)][0], atol=1)  # all grey


def test_a_flat_video_has_no_colour_error(tmp_path):
    asset = build_animal("quadruped", name="quad")
    folder = make_video(asset, tmp_path, frames=3, size=32, seed=1)
    from zooctl.benchdata.appearance import fit_psnr

    assert fit_psnr(tmp_path, "nothing", folder) is None


def test_bench_make_refuses_an_unknown_appearance(tmp_path):
    from zooctl.errors import UsageError

    with pytest.raises(UsageError, match="--appearance"):
        make_video(build_animal("quadruped", name="quad"), tmp_path, frames=2, size=32, appearance="oil")


def test_bench_run_reports_the_colour_error(tmp_path, store):
    """A fit of a textured video gets ``view_psnr`` and ``input_psnr`` in its row and the table;
    with ``texture`` off (the template's colours) they are lower in sample."""
    from fit_helpers import tiny_overrides

    from zooctl.benchdata.run import markdown_table, run_benchmark
    from zooctl.store.bank import Bank

    asset = build_animal("quadruped", name="quad")
    Bank(store).add(asset)
    make_video(asset, tmp_path / "v", frames=4, size=64, seed=1, appearance="textured")
    make_video(asset, tmp_path / "flat", frames=3, size=32, seed=1)
    res = run_benchmark(
        tmp_path / "v", store, own_template=True, known_camera=True, overrides=tiny_overrides()
    )
    row = res["rows"][0]
    assert 0 < row["view_psnr"] < 60 and 0 < row["input_psnr"] < 60
    assert res["summary"]["full"]["view_psnr"] == pytest.approx(row["view_psnr"])
    table = markdown_table(res)
    assert "held-out PSNR" in table and f"{row['view_psnr']:.2f}" in table
    plain = run_benchmark(
        tmp_path / "v",
        store,
        own_template=True,
        known_camera=True,
        overrides={**tiny_overrides(), "texture": False},
    )
    assert plain["rows"][0]["input_psnr"] < row["input_psnr"]
    flat = run_benchmark(tmp_path / "flat", store, own_template=True, overrides=tiny_overrides())
    assert "view_psnr" not in flat["rows"][0] and "| n/a |" in markdown_table(flat)


def test_a_world_background_moves_with_the_orbiting_camera_and_a_still_one_does_not(tmp_path):
    """`bench make --background world`: the scene is fixed in the world, so the camera's turn read
    from it (`zooctl.video.camera_motion`) is the benchmark camera's own; with the default still
    background the scene stands still in the frame and reads as a camera at rest. The animal is
    drawn the same over either."""
    from zooctl.video.camera_motion import background_motion

    asset = build_animal("quadruped", name="quad")
    still = make_video(asset, tmp_path / "still", frames=13, size=160, seed=1, appearance="textured")
    world = make_video(
        asset, tmp_path / "world", frames=13, size=160, seed=1, appearance="textured", background="world"
    )
    assert json.loads((world / "meta.json").read_text())["background"] == "world"
    assert "background" not in json.loads((still / "meta.json").read_text())
    with np.load(still / "video.npz") as s, np.load(world / "video.npz") as w:
        np.testing.assert_array_equal(s["masks"], w["masks"])
        np.testing.assert_array_equal(s["frames"][s["masks"]], w["frames"][w["masks"]])
        C, K = w["gt_cam_rotation"], w["intrinsics"]
        moved = background_motion(w["frames"], w["masks"], float(K[0]), (K[2], K[3]))
        rest = background_motion(s["frames"], s["masks"], float(K[0]), (K[2], K[3]))
    truth = C[-1] @ C[0].T
    turn = np.degrees(np.arccos(np.clip((np.trace(truth) - 1) / 2, -1, 1)))
    assert turn > 10.0  # the camera did orbit
    err = np.degrees(np.arccos(np.clip((np.trace(moved.rotations[-1] @ truth.T) - 1) / 2, -1, 1)))
    assert moved.known.all() and err < 0.1 * turn
    assert np.allclose(rest.rotations, np.eye(3), atol=1e-3)


def test_a_turning_animal_turns_in_the_world_by_the_angle_asked(tmp_path):
    """`bench make --turn 90`: the same video's animal, turned steadily about the vertical through
    its first frame's centre, 90 degrees by the last frame (the sign drawn by the seed); its
    joints with it; the camera's orbit (its distance framing the whole clip) and the bones' motion
    unchanged."""
    from zooctl.benchdata.make import turn_in_world

    asset = build_animal("quadruped", name="quad")
    held = make_video(asset, tmp_path / "held", frames=9, size=64, seed=2)
    turned = make_video(asset, tmp_path / "turned", frames=9, size=64, seed=2, turn=90.0)
    signed = json.loads((turned / "meta.json").read_text())["turn"]
    assert abs(signed) == 90.0 and "turn" not in json.loads((held / "meta.json").read_text())
    with np.load(held / "video.npz") as h, np.load(turned / "video.npz") as t:
        heading = signed * np.arange(9) / 8
        pivot = 0.5 * (h["gt_vertices"][0].min(0) + h["gt_vertices"][0].max(0))
        np.testing.assert_allclose(
            t["gt_vertices"], turn_in_world(h["gt_vertices"], heading, pivot), atol=1e-4
        )
        np.testing.assert_allclose(t["gt_joints"], turn_in_world(h["gt_joints"], heading, pivot), atol=1e-4)
        np.testing.assert_array_equal(t["gt_cam_rotation"], h["gt_cam_rotation"])
        assert (t["masks"][-1] != h["masks"][-1]).any()  # the animal turned in the frame too
        # the turn is a rotation about +Y: heights are kept, the first frame untouched
        np.testing.assert_allclose(t["gt_vertices"][..., 1], h["gt_vertices"][..., 1], atol=1e-5)
    with pytest.raises(Exception, match="--turn"):
        make_video(asset, tmp_path / "bad", frames=3, size=32, turn=-5.0)
