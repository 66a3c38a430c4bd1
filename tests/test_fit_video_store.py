"""`zooctl fit PATH` adds the video to the video store first (as `zooctl video add` does) and reuses it."""

from __future__ import annotations

import numpy as np
import pytest
from fit_helpers import tiny_fit_config, write_davis_folder

from zooctl.errors import UsageError
from zooctl.fit.job import fit_job
from zooctl.store.bank import Bank
from zooctl.store.fits import FitStore
from zooctl.store.videos import VideoStore


@pytest.fixture(scope="module")
def davis_folder(tmp_path_factory):
    """A 2-bone tube filmed by `bench make`, written out as a DAVIS folder (JPEGImages + Annotations)."""
    from zooctl.benchdata.make import make_video
    from zooctl.fit.inputs import load_bench_video
    from zooctl.rig.synthetic import tube_asset

    root = tmp_path_factory.mktemp("davis")
    asset = tube_asset(bones=3, name="tube")
    video = load_bench_video(make_video(asset, root / "bench", frames=5, size=48, seed=2))
    folder = write_davis_folder(root / "tubecam", video.frames, video.masks)
    return asset, folder, video.masks


def test_fit_of_a_path_stores_the_video_once(davis_folder, store):
    asset, folder, masks = davis_folder
    Bank(store).add(asset)
    rec = fit_job(str(folder), store, tiny_fit_config(), name="a", template="tube", outputs=("loss",))
    videos = VideoStore(store)
    assert videos.names() == ["tubecam"] and rec["stored_video"] == "tubecam"
    stored = videos.get("tubecam")
    assert stored.segmenter["name"] == "masks"  # the DAVIS annotations, not a segmenter's guess
    assert np.array_equal(stored.masks, masks) and stored.flow_forward.shape[0] == len(masks) - 1
    assert rec["mask_source"] == "masks" and rec["status"] == "done"

    before = videos.path("tubecam").stat().st_mtime_ns
    rec2 = fit_job(str(folder), store, tiny_fit_config(), name="b", template="tube", outputs=("loss",))
    assert rec2["stored_video"] == "tubecam" and videos.names() == ["tubecam"]  # reused, not re-added
    assert videos.path("tubecam").stat().st_mtime_ns == before

    # Automatic masks (the default segmenter from a first-frame box) for the same frames are another stored
    # video; the first one stays as it was, and the same request again reuses the second.
    ys, xs = np.nonzero(masks[0])
    box = (int(xs.min()) - 2, int(ys.min()) - 2, int(np.ptp(xs)) + 5, int(np.ptp(ys)) + 5)
    auto = {"masks": "auto", "box": box, "outputs": ("loss",), "template": "tube"}
    rec3 = fit_job(str(folder), store, tiny_fit_config(), name="c", **auto)
    assert rec3["stored_video"] == "tubecam-2" and videos.names() == ["tubecam", "tubecam-2"]
    assert fit_job(str(folder), store, tiny_fit_config(), name="c2", **auto)["stored_video"] == "tubecam-2"
    assert videos.get("tubecam-2").segmenter["name"] == "animalnet"  # the default segmenter
    assert np.array_equal(videos.get("tubecam").masks, masks)

    # A stored video can be fitted by name.
    rec4 = fit_job("tubecam", store, tiny_fit_config(), name="d", template="tube", outputs=("loss",))
    assert rec4["stored_video"] == "tubecam" and sorted(FitStore(store).names()) == ["a", "b", "c", "c2", "d"]


def test_box_needs_automatic_masks(davis_folder, store):
    asset, folder, _ = davis_folder
    Bank(store).add(asset)
    with pytest.raises(UsageError, match="--box"):
        fit_job(str(folder), store, tiny_fit_config(), name="x", template="tube", box=(1, 1, 20, 20))
    assert VideoStore(store).names() == []  # nothing stored on a usage error


def test_the_summary_line_says_what_the_mask_iou_is_measured_against():
    from zooctl.cli.fit import masks_measured_against

    assert masks_measured_against("masks") == "your masks"
    assert "not ground truth" in masks_measured_against("grabcut")
    assert "not ground truth" in masks_measured_against("auto")
    assert "ground truth" not in masks_measured_against("given")


def test_a_video_stored_by_another_fit_meanwhile_is_reused(davis_folder, store):
    """Two fits of one new file started together both plan to add it under the same name; the one
    that finishes preprocessing second reuses what the first stored instead of failing."""
    from pathlib import Path

    from zooctl.fit.job import add_planned_video, plan_stored_video, store_video

    _, folder, masks = davis_folder
    name, reused, opts = plan_stored_video(Path(folder), store, None)
    assert (name, reused) == ("tubecam", False)
    assert store_video(Path(folder), store, None) == "tubecam"  # the other fit, faster
    assert add_planned_video(Path(folder), store, None, None, opts) == "tubecam"
    videos = VideoStore(store)
    assert videos.names() == ["tubecam"] and np.array_equal(videos.get("tubecam").masks, masks)
