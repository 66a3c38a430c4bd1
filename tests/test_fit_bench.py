"""`bench make` ground truth and `bench run`'s table, on a tiny tube video."""

from __future__ import annotations

import json

import numpy as np
import pytest
from fit_helpers import tiny_overrides

from zooctl.benchdata.make import make_video
from zooctl.benchdata.run import markdown_table, run_benchmark
from zooctl.errors import UsageError
from zooctl.rig.synthetic import tube_asset

TINY = tiny_overrides()


def test_bench_make_ground_truth_is_consistent(tmp_path):
    """The saved masks are the projection of the saved vertices through the saved cameras."""
    import torch

    from zooctl.render.camera import Camera
    from zooctl.render.raster import rasterize

    asset = tube_asset(bones=3, name="tube")
    folder = make_video(asset, tmp_path, frames=13, size=48, seed=2)
    z = np.load(folder / "video.npz")
    assert z["frames"].shape == (13, 48, 48, 3) and z["flow"].shape == (12, 48, 48, 2)
    assert z["gt_novel_vertices"].shape == z["gt_vertices"].shape[1:]
    t = 7
    K = torch.as_tensor(z["intrinsics"][None], dtype=torch.float32)
    cam = Camera(
        K,
        torch.as_tensor(z["gt_cam_rotation"][t : t + 1], dtype=torch.float32),
        torch.as_tensor(z["gt_cam_translation"][t : t + 1], dtype=torch.float32),
        48,
        48,
    )
    sil = (
        rasterize(
            torch.as_tensor(z["gt_vertices"][t : t + 1]),
            torch.as_tensor(z["gt_faces"], dtype=torch.long),
            cam,
        )
        .mask[0]
        .numpy()
    )
    assert (sil == z["masks"][t]).mean() > 0.99
    # The camera moves (15-22.5 degrees per 12 frames) and the pose changes.
    assert not np.allclose(z["gt_cam_rotation"][0], z["gt_cam_rotation"][12])
    assert np.abs(z["gt_vertices"][12] - z["gt_vertices"][0]).max() > 1e-3
    assert json.loads((folder / "meta.json").read_text())["asset"] == "tube"


def test_bench_run_table(tmp_path, store):
    from zooctl.store.bank import Bank

    tube = tube_asset(bones=3, name="tube")
    other = tube_asset(bones=2, name="tube2", radius=0.2)
    Bank(store).add(tube)
    Bank(store).add(other)
    make_video(tube, tmp_path / "v", frames=3, size=32, seed=0)
    res = run_benchmark(
        tmp_path / "v", store, ablations=["full", "no-flow"], template="tube2", overrides=TINY
    )
    assert [r["ablation"] for r in res["rows"]] == ["full", "no-flow"]
    row = res["rows"][0]
    assert row["template"] == "tube2" and 0 <= row["mask_iou"] <= 1 and row["miou"] is not None
    table = markdown_table(res)
    assert "| full | 1 |" in table and "no-flow" in table
    assert "Camera motion: estimated" in table
    own = run_benchmark(tmp_path / "v", store, own_template=True, known_camera=True, overrides=TINY)
    assert own["rows"][0]["template"] == "tube" and own["own_template"] and own["known_camera"]
    assert "each video's own asset" in markdown_table(own) and "Camera motion: known" in markdown_table(own)
    with pytest.raises(UsageError, match="exclude each other"):
        run_benchmark(tmp_path / "v", store, template="tube2", own_template=True)


def test_reanimation_uses_the_scale_of_the_frame_it_starts_from(tmp_path):
    """Re-animation poses the last frame's fit: a fit whose depth drifts on the other frames (a
    monocular fit is only known up to a scale per frame) must not move its scale."""
    import torch

    from zooctl.fit.config import FitConfig
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.run import fit_video
    from zooctl.metrics import evaluate_fit

    asset = tube_asset(bones=3, name="tube")
    video = load_fit_video(make_video(asset, tmp_path / "v", frames=4, size=32, seed=0))
    res = fit_video(video, asset, FitConfig.from_dict(json.loads(json.dumps(TINY))))
    before = evaluate_fit(res, frames=4)
    with torch.no_grad():
        res.scene.root_translation[:-1] *= 2.0  # every frame but the last twice as far
    after = evaluate_fit(res, frames=4)
    assert after["reanimation"] == before["reanimation"]
