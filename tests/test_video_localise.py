"""The animal localiser (ImageNet class maps + motion) and the segmenter's seeding without a box,
from a box on any frame, and what it reports."""

from __future__ import annotations

import numpy as np
import pytest
from cli_helpers import run_inprocess
from conftest import VIDEOS_DIR, needs_shared_videos
from PIL import Image
from video_helpers import iou, moving_object_video

from zooctl.errors import UsageError
from zooctl.video import cues
from zooctl.video.grabcut import GrabCutTracker
from zooctl.video.localise import Localiser, class_name, main_region


@pytest.fixture(scope="module")
def synthetic():
    return moving_object_video(t=10, h=96, w=128)


def test_class_names():
    assert class_name(207) == "golden retriever" and class_name(354) == "Arabian camel"
    assert class_name(200) == "dog #200" and class_name(12) == "bird #12"


@needs_shared_videos
def test_localiser_sees_the_dog_where_it_is():
    from zooctl.video.decode import decode

    seq = VIDEOS_DIR / "dog"
    frame = decode(seq, max_size=427, max_frames=1).frames[0]
    with Image.open(sorted((seq / "Annotations").glob("*.png"))[0]) as im:
        truth = np.asarray(im.resize(frame.shape[1::-1], Image.Resampling.NEAREST)) != 0
    ev = Localiser().evidence(frame)
    assert ev.animal.shape == truth.shape and ev.animal.max() == pytest.approx(1.0)
    assert ev.animal_prob > 0.3
    assert 151 <= ev.classes[0][0] <= 268  # a dog breed
    region, _ = main_region(ev.animal)
    assert (region & truth).sum() > 0.5 * region.sum()  # the evidence lies on the dog
    # a flat grey frame holds no animal worth a seed
    assert Localiser().evidence(np.full_like(frame, 128)).animal_prob < 0.3


def test_no_box_finds_the_moving_object(synthetic):
    frames, masks = synthetic
    seg = GrabCutTracker()
    got = seg.segment(frames)
    assert iou(got, masks) > 0.6
    how = seg.report["seeding"]
    assert how[seg.report["seed_frame"]] == "localiser" and len(how) == len(frames)
    assert set(how) <= {"localiser", "tracked", "re-seeded", "empty"}


def test_box_on_a_later_frame_tracks_both_ways(synthetic):
    frames, masks = synthetic
    seg = GrabCutTracker(localise=False)
    got = seg.segment(frames, box=cues.box_of(masks[6]), box_frame=6)
    assert seg.report["seeding"][6] == "box" and seg.report["seed_frame"] == 6
    assert iou(got[:6], masks[:6]) > 0.7 and iou(got[6:], masks[6:]) > 0.7
    with pytest.raises(UsageError, match="--box-frame 10 is not a frame of this 10-frame video"):
        seg.segment(frames, box=cues.box_of(masks[0]), box_frame=10)


def test_cli_box_frame_and_show_report_seeding(store, synthetic, tmp_path, capsys):
    frames, masks = synthetic
    folder = tmp_path / "clip"
    folder.mkdir()
    for i, f in enumerate(frames):
        Image.fromarray(f).save(folder / f"{i:05d}.png")
    x, y, w, h = cues.box_of(masks[3])
    r = run_inprocess(capsys, "video", "add", str(folder), "--box-frame", "3", "-q")
    assert r.code == 2 and "--box-frame places --box" in r.err
    r = run_inprocess(
        capsys, "video", "add", str(folder), "--box", f"{x},{y},{w},{h}", "--box-frame", "3", "-q"
    )
    assert r.code == 0, r.err
    r = run_inprocess(capsys, "video", "show", "clip")
    assert r.code == 0 and "seeding: 1 box" in r.out and "(first seed on frame 3)" in r.out, r.out
