"""Analysis by synthesis (`zooctl.fit.refine_masks`): a fit's reprojection re-segments its video,
then one fit again on the refined masks."""

from __future__ import annotations

import numpy as np
import pytest
from fit_helpers import write_davis_folder

from zooctl.fit.refine_masks import REFINED_FILE, load_refined

pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def tube_video(tmp_path_factory):
    """A 3-bone tube filmed by `bench make`, as a DAVIS folder with its masks."""
    from zooctl.benchdata.make import make_video
    from zooctl.fit.inputs import load_bench_video
    from zooctl.rig.synthetic import tube_asset

    root = tmp_path_factory.mktemp("refine")
    asset = tube_asset(bones=3, name="tube")
    video = load_bench_video(make_video(asset, root / "bench", frames=4, size=64, seed=2))
    masks = video.masks.copy()
    folder = write_davis_folder(root / "tubecam", video.frames, masks)
    return asset, folder, masks


def test_refine_and_refit_leaves_the_video_masks_and_writes_its_own(tube_video, tmp_path):
    from fit_helpers import tiny_fit_config

    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.refine_masks import refine_and_refit
    from zooctl.fit.run import fit_video

    asset, folder, masks = tube_video
    video = load_fit_video(folder)
    first = fit_video(video, asset, tiny_fit_config(4))
    refit, info = refine_and_refit(first, tmp_path)
    saved = load_refined(tmp_path / REFINED_FILE)
    assert np.array_equal(video.masks, masks), "the input video's masks are not changed"
    assert np.array_equal(refit.video.masks, saved["masks"]) and refit.video is not video
    assert refit.template is asset and refit.iou is not None
    assert saved["prior"].shape == masks.shape and saved["prior"].any()
    # the refined masks are the prior's re-segmentation: where the prior and mask agree deep
    # inside, the refined mask holds the animal
    both = saved["prior"] & masks
    assert saved["masks"][both].mean() > 0.9
    assert info["before"]["mask_iou"] > 0 and info["from_masks"] == video.mask_source
