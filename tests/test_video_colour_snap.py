"""The masks snapped to the animal's colours: a blob of background a mask took in goes, a video
whose animal wears its ground's colours keeps its masks, and `zooctl video add` runs it and says so."""

from __future__ import annotations

import numpy as np
import pytest
from cli_helpers import run_inprocess
from video_helpers import iou

from zooctl.video.colour_snap import separation, snap_frame, snap_video


def _scene(seed: int, animal_rgb, ground_rgb, t: int = 4, h: int = 120, w: int = 160):
    """(T, H, W, 3) frames of an ellipse of ``animal_rgb`` moving over a noisy ground of
    ``ground_rgb``; (T, H, W) true masks; and masks that also take in a blob of ground beside it."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[:h, :w]
    frames, truth, bled = [], [], []
    for i in range(t):
        cx, cy = 60 + 4 * i, 70
        body = ((xx - cx) / 28.0) ** 2 + ((yy - cy) / 14.0) ** 2 <= 1
        blob = ((xx - cx - 10) / 30.0) ** 2 + ((yy - cy + 28) / 18.0) ** 2 <= 1
        f = np.clip(np.array(ground_rgb) + rng.normal(0, 12, (h, w, 3)), 0, 255)
        f[body] = np.clip(np.array(animal_rgb) + rng.normal(0, 8, (int(body.sum()), 3)), 0, 255)
        frames.append(f.astype(np.uint8))
        truth.append(body)
        bled.append(body | blob)
    return np.stack(frames), np.stack(truth), np.stack(bled)


def test_a_blob_of_ground_the_mask_took_in_goes():
    frames, truth, bled = _scene(0, (90, 90, 95), (60, 140, 50))
    got = snap_frame(frames[0], bled[0])
    assert iou(bled[0], truth[0]) < 0.7
    assert iou(got, truth[0]) > 0.9
    # too small a mask, or one without background around it, comes back as it was
    tiny = np.zeros_like(truth[0])
    tiny[5:8, 5:8] = True
    assert (snap_frame(frames[0], tiny) == tiny).all()
    full = np.ones_like(truth[0])
    assert (snap_frame(frames[0], full) == full).all()


def test_separation_tells_distinct_colours_from_shared_ones():
    from zooctl.video.colour_snap import BINS
    from zooctl.video.cues import lab_bins

    frames, truth, bled = _scene(1, (90, 90, 95), (60, 140, 50))
    lab = lab_bins(frames[0], BINS)
    assert separation(lab, truth[0], 6) > 0.8
    assert separation(lab, bled[0], 6) < separation(lab, truth[0], 6)
    same, t2, _ = _scene(1, (60, 140, 50), (60, 140, 50))
    assert separation(lab_bins(same[0], BINS), t2[0], 6) < 0.3
    assert np.isnan(separation(lab, np.zeros_like(truth[0]), 6))


def test_a_video_is_snapped_only_where_the_colours_then_stand_apart():
    frames, truth, bled = _scene(2, (90, 90, 95), (60, 140, 50))
    got, report = snap_video(frames, bled)
    assert report["snapped"] and report["separation_gain"] > report["min_gain"]
    assert np.mean([iou(m, t) for m, t in zip(got, truth)]) > 0.9
    # the same masks over an animal of its ground's colours: GrabCut cannot tell them apart, the
    # gain stays small, and the video keeps the masks it had
    same, _, bled_same = _scene(2, (60, 140, 50), (60, 140, 50))
    kept, report = snap_video(same, bled_same)
    assert not report["snapped"] and kept is bled_same
    # a threshold no gain reaches keeps any video's masks; the snap is the same on every thread count
    kept, report = snap_video(frames, bled, min_gain=1.0)
    assert kept is bled and not report["snapped"]
    empty, report = snap_video(frames, np.zeros_like(bled))
    assert report["separation_gain"] is None and not report["snapped"]


def test_the_snap_does_not_depend_on_the_threads(monkeypatch):
    frames, _, bled = _scene(3, (200, 120, 60), (60, 140, 50), t=6)
    one_thread = {}
    for n in ("1", "4"):
        monkeypatch.setenv("OMP_NUM_THREADS", n)
        one_thread[n] = np.asarray(snap_video(frames, bled)[0])
    assert (one_thread["1"] == one_thread["4"]).all()


@pytest.mark.parametrize("snap", [True, False])
def test_video_add_snaps_and_video_show_says_so(tmp_path, monkeypatch, capsys, snap):
    import cv2

    frames, _, _ = _scene(4, (90, 90, 95), (60, 140, 50), t=8)
    folder = tmp_path / "frames"
    folder.mkdir()
    for i, f in enumerate(frames):
        cv2.imwrite(str(folder / f"{i:05d}.png"), cv2.cvtColor(f, cv2.COLOR_RGB2BGR))
    monkeypatch.setenv("ZOOCTL_STORE", str(tmp_path / "store"))
    args = ["video", "add", str(folder), "--name", "v", "-q", "--box", "30,50,60,40"]
    if not snap:
        args += ["--seg-option", "snap=false"]
    got = run_inprocess(capsys, *args)
    assert got.code == 0, got.err
    got = run_inprocess(capsys, "video", "show", "v")
    assert got.code == 0, got.err
    assert ("snapped to the animal's colours" in got.out) == snap


def test_a_video_left_as_it_was_costs_a_fixed_number_of_cuts_whatever_its_length(monkeypatch):
    import zooctl.video.colour_snap as cs

    calls = []
    real = cs.snap_frame

    def counted(frame, mask, *a, **k):
        calls.append(1)
        return real(frame, mask, *a, **k)

    monkeypatch.setattr(cs, "snap_frame", counted)
    same, _, bled = _scene(5, (60, 140, 50), (60, 140, 50), t=7)
    assert not cs.snap_video(same, bled, looks=3)[1]["snapped"]
    assert len(calls) == 3  # frames 0, 3 and the last
    calls.clear()
    same, _, bled = _scene(5, (60, 140, 50), (60, 140, 50), t=30, w=240)
    assert not cs.snap_video(same, bled)[1]["snapped"]
    assert len(calls) == cs.LOOKS < 30
    calls.clear()
    frames, _, bled = _scene(5, (90, 90, 95), (60, 140, 50), t=7)
    assert cs.snap_video(frames, bled, looks=3)[1]["snapped"] and len(calls) == 7


def test_the_frames_looked_at_span_the_video():
    from zooctl.video.colour_snap import looked_at_frames

    assert looked_at_frames(0) == []
    assert looked_at_frames(1) == [0]
    assert looked_at_frames(5, 8) == [0, 1, 2, 3, 4]
    assert looked_at_frames(7, 3) == [0, 3, 6]
    got = looked_at_frames(300, 8)
    assert len(got) == 8 and got[0] == 0 and got[-1] == 299
    assert max(np.diff(got)) - min(np.diff(got)) <= 1


def test_frames_waiting_in_scratch_files_give_the_same_snapped_masks():
    from zooctl.video.scratch import ScratchArray

    frames, _, bled = _scene(6, (90, 90, 95), (60, 140, 50), t=5)

    def lazy(a):
        out = ScratchArray(len(a), a.shape[1:], a.dtype)
        for i, x in enumerate(a):
            out[i] = x
        return out

    in_memory, _ = snap_video(frames, bled)
    from_files, report = snap_video(lazy(frames), lazy(bled))
    assert report["snapped"] and isinstance(from_files, ScratchArray)
    assert (np.stack([np.asarray(m) for m in from_files]) == np.asarray(in_memory)).all()
