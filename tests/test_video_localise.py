"""The animal localiser (ImageNet class maps + motion) and the segmenter's seeding without a box,
from a box on any frame, and what it reports."""

from __future__ import annotations

import numpy as np
import pytest
from cli_helpers import run_inprocess
from conftest import VIDEOS_DIR, needs_shared_videos
from PIL import Image
from video_helpers import iou, moving_object_video, write_pngs

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


def test_tracked_masks_are_checked_on_the_keyframes_start_looked_at():
    seg = GrabCutTracker(key_every=4)
    mask = np.zeros((8, 8), bool)
    mask[2:6, 2:6] = True
    checked = [i for i in range(10) if seg._due(i, 10, mask, mask)]
    assert checked == [0, 4, 8, 9]  # `_start`'s keyframes: no extra look while the mask holds
    assert seg._due(5, 10, mask & False, mask)  # lost: look again at once


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
    folder = write_pngs(tmp_path / "clip", frames)
    x, y, w, h = cues.box_of(masks[3])
    r = run_inprocess(capsys, "video", "add", str(folder), "--box-frame", "3", "-q")
    assert r.code == 2 and "--box-frame places --box" in r.err
    box = ("--box", f"{x},{y},{w},{h}", "--box-frame", "3")
    r = run_inprocess(capsys, "video", "add", str(folder), *box, "--seg-option", "localise=false", "-q")
    assert r.code == 0, r.err
    r = run_inprocess(capsys, "video", "show", "clip")
    assert r.code == 0 and "seeding: 1 box" in r.out and "(first seed on frame 3)" in r.out, r.out
    assert "the box on frame 3 seeded the masks" in r.out
    # with the localiser (the default) the box chooses the animal and the localiser seeds it
    r = run_inprocess(capsys, "video", "add", str(folder), *box, "--name", "clip2", "-q")
    assert r.code == 0, r.err
    r = run_inprocess(capsys, "video", "show", "clip2")
    assert r.code == 0 and "seeding: 1 localiser" in r.out, r.out
    assert "the box on frame 3 chose the animal" in r.out


def test_an_animal_that_leaves_the_frame_is_found_again(synthetic):
    """Frames 4-6 show only the panning background: they stay empty, and the object is taken up
    again when it is back (the localiser re-seeds where tracking lost it)."""
    from video_helpers import texture

    frames, masks = (a.copy() for a in synthetic)
    bg = (texture(96, 128 + 40, 0) * 0.5 + np.array([60, 90, 60])).astype(np.uint8)
    for i in (4, 5, 6):
        frames[i], masks[i] = bg[:, 2 * i : 2 * i + 128], False
    seg = GrabCutTracker()
    got = seg.segment(frames)
    assert not got[4:6].any()  # no background taken for the animal
    present = [i for i in range(10) if masks[i].any()]
    assert np.mean([iou(got[i], masks[i]) for i in present]) > 0.8
    assert "re-seeded" in seg.report["seeding"] or seg.report["seed_frame"] < 4


def test_main_region_is_the_one_with_most_evidence():
    score = np.zeros((60, 80), np.float32)
    score[5:20, 5:20] = 0.9  # small, sure
    score[30:55, 40:75] = 0.7  # big, less sure: more evidence in all
    region, count = main_region(score)
    assert count == 2 and region[40, 60] and not region[10, 10]


def test_a_localiser_seed_leaves_out_what_moves_with_the_animal_but_is_not_it():
    """A dark bird over a reflection that moves with it and shares its darkness (both in the
    localiser's loose box): the seed learns the bird's colours from where the class map is surest,
    so the reflection, which the blurry class map also covers more weakly, stays background."""
    import cv2
    from video_helpers import texture

    h, w = 96, 128
    frame = (texture(h, w, 0) * 0.5 + np.array([60, 90, 60])).astype(np.uint8)
    shapes = [np.zeros((h, w), np.uint8) for _ in range(2)]
    cv2.ellipse(shapes[0], (64, 38), (30, 12), 0, 0, 360, 1, -1)
    cv2.ellipse(shapes[1], (64, 62), (34, 14), 0, 0, 360, 1, -1)
    bird = shapes[0] > 0
    reflection = (shapes[1] > 0) & ~bird
    reflection[:40] = False
    frame[bird] = (texture(h, w, 1) * 0.2 + np.array([150, 150, 160]))[bird]  # grey
    frame[reflection] = (texture(h, w, 2) * 0.2 + np.array([20, 50, 25]))[reflection]  # dark green
    residual = np.where(bird | reflection, 3.0, 0.1).astype(np.float32)  # both move alike
    yy, xx = np.mgrid[0:h, 0:w]
    animal = np.exp(-(((xx - 64) / 30.0) ** 2 + ((yy - 38) / 14.0) ** 2)).astype(np.float32)
    x, y, bw, bh = cues.box_of(bird | reflection)
    box, bins = (x - 6, y - 6, bw + 12, bh + 12), cues.lab_bins(frame)
    got = {}
    for q in (0.0, 0.5):
        cv2.setRNGSeed(0)  # GrabCut's k-means start, as `segment` sets it
        got[q] = GrabCutTracker(core_quantile=q)._seed_in_box(frame, bins, residual, box, animal)
    assert iou(got[0.0], bird | reflection) > 0.9  # one pass from the whole seed takes both
    assert iou(got[0.5], bird) > 0.9 and not (got[0.5] & reflection).any()
    # a class map sure of nothing (no pixel over 0.7 of a peak) says nothing against the reflection
    cv2.setRNGSeed(0)
    unsure = GrabCutTracker()._seed_in_box(frame, bins, residual, box, 0.6 * animal)
    assert iou(unsure, bird | reflection) > 0.9
    with pytest.raises(UsageError, match="core_quantile"):
        GrabCutTracker(core_quantile=1.0)


class RedLocaliser:
    """A localiser the test builds: its class map is the frame's redness, blurred as a class map is
    (the shipped classifier sees no animal in synthetic ellipses); sure of an animal wherever
    something is red."""

    def evidence(self, frame):
        import cv2

        from zooctl.video.localise import Evidence

        f = frame.astype(np.float32)
        red = np.clip((f[..., 0] - 0.5 * (f[..., 1] + f[..., 2])) / 100.0, 0.0, 1.0)
        cam = cv2.GaussianBlur(red, (0, 0), 6)
        cam = cam / max(float(cam.max()), 1e-6)
        return Evidence(cam.astype(np.float32), 0.9, 0.99 if red.max() > 0.5 else 0.0, [(207, 0.9)])


def two_animals(t: int = 10, h: int = 96, w: int = 160, near: bool = False):
    """``moving_object_video`` with a second, smaller red object moving slower at the bottom right
    (``near``: moving left, close under the big one): frames and the true masks of the big and of
    the small object."""
    import cv2

    frames, big = moving_object_video(t=t, h=h, w=w)
    frames = frames.copy()
    small = np.zeros_like(big)
    for i in range(t):
        m = np.zeros((h, w), np.uint8)
        centre = (w - 30 - 2 * i, 3 * h // 4) if near else (w - 30 + i, h - 12)
        cv2.ellipse(m, centre, (12, 9), 0, 0, 360, 1, -1)
        small[i] = (m > 0) & ~big[i]
        frames[i][small[i]] = (200, 40, 40)
    return frames, big, small


def test_a_box_chooses_which_animal_the_localiser_seeds():
    """Two red animals: without a box the localiser takes the bigger; a box around the smaller one
    on frame 5 makes every frame's mask the smaller one, seeded where the localiser sees it (not
    necessarily on the box's frame); a box where the localiser sees no animal seeds from the box."""
    frames, big, small = two_animals()
    seg = GrabCutTracker()
    seg._loc = RedLocaliser()
    auto = seg.segment(frames)
    assert iou(auto, big) > 0.7
    seg = GrabCutTracker()
    seg._loc = RedLocaliser()
    got = seg.segment(frames, box=cues.box_of(small[5]), box_frame=5)
    assert seg.report["box_use"] == "chose the animal" and seg.report["box_frame"] == 5
    assert seg.report["seeding"][seg.report["seed_frame"]] == "localiser"
    assert np.mean([iou(g, m) for g, m in zip(got, small)]) > 0.6
    assert not (got & big).any()
    # grey background only in the box: nothing the localiser calls an animal, so the box seeds
    seg = GrabCutTracker()
    seg._loc = RedLocaliser()
    seg.segment(frames, box=(2, 2, 30, 20), box_frame=5)
    assert seg.report["box_use"] == "seeded" and seg.report["seeding"][5] == "box"
    with pytest.raises(UsageError, match="does not cover"):
        seg.segment(frames, box=(500, 500, 10, 10), box_frame=5)


def test_a_box_the_localiser_result_does_not_fit_seeds_from_the_box():
    """The small animal close under the big one: their blurry class maps join, the localiser's seed
    takes the big one, which does not fit the box on its frame; the box's own pixels seed instead."""
    frames, big, small = two_animals(near=True)
    seg = GrabCutTracker()
    seg._loc = RedLocaliser()
    got = seg.segment(frames, box=cues.box_of(small[5]), box_frame=5)
    assert seg.report["box_use"] == "seeded" and seg.report["seeding"][5] == "box"
    assert np.mean([iou(g, m) for g, m in zip(got, small)]) > 0.8


def test_a_box_region_is_carried_along_the_flow():
    from zooctl.video import hint

    t, h, w = 5, 40, 60
    region = np.zeros((h, w), bool)
    region[10:20, 10:20] = True
    forward = np.zeros((t - 1, h, w, 2), np.float32)
    forward[..., 0] = 3.0  # everything moves 3 px right a frame
    backward = -forward
    got = hint.carry(region, forward, backward, 2)
    for i in range(t):
        moved = np.roll(region, 3 * (i - 2), axis=1)
        assert (got[i] & moved).sum() == moved.sum()  # covers it, with a band around
        assert got[i].sum() < 2 * moved.sum()
    parts = np.zeros((h, w), bool)
    parts[5:15, 5:15] = parts[25:35, 40:50] = True
    touched = hint.touching(parts, region)
    assert touched[5:15, 5:15].all() and not touched[25:35, 40:50].any()


def test_a_mask_agrees_with_the_box_it_was_drawn_around():
    from zooctl.video import hint

    mask = np.zeros((60, 80), bool)
    mask[20:40, 30:50] = True
    assert hint.agrees(mask, (28, 18, 24, 24))  # a loose box
    assert hint.agrees(mask, (32, 22, 16, 16))  # a tight box cutting paws off
    assert not hint.agrees(mask, (0, 0, 20, 15))  # another place
    assert not hint.agrees(mask, (0, 0, 80, 60))  # the box is the whole frame, the mask a corner of it
    assert not hint.agrees(mask & False, (28, 18, 24, 24))


def test_with_flip_a_frame_and_its_mirror_image_give_mirrored_evidence():
    """``flip`` averages a frame's look with its mirror image's: the evidence of a mirrored frame is
    the frame's mirrored, its numbers the same, so which way the animal faces decides nothing."""
    from zooctl.benchdata.composites import composite
    from zooctl.procedural.random import random_assets

    frame = composite(random_assets(1, seed=2), np.random.default_rng(5), (160, 120)).frames[0]
    mirror = np.ascontiguousarray(frame[:, ::-1])
    loc = Localiser(width=160, flip=True)
    a, b = loc.evidence(frame), loc.evidence(mirror)
    assert a.confidence == b.confidence and a.animal_prob == b.animal_prob and a.classes == b.classes
    assert np.abs(a.animal - b.animal[:, ::-1]).max() < 1e-4
    # one look alone is not mirror-symmetric (what the option is for), nor is flip a no-op
    single = Localiser(width=160)
    assert single.evidence(frame).confidence != single.evidence(mirror).confidence
    assert single.evidence(frame).confidence != a.confidence
