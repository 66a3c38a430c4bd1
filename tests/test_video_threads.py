"""`video add` on two cores: the tracker's two directions side by side, the network's looks taken
while it tracks and the file written behind give the same masks and file, run after run."""

from __future__ import annotations

import threading

import cv2
import numpy as np
import pytest
from video_helpers import assert_same_video, iou, moving_object_video

from zooctl.errors import StoreError
from zooctl.store.h5 import describe_h5
from zooctl.store.videos import VideoStore, VideoWriter
from zooctl.video import cues
from zooctl.video.animalnet import AnimalNetSegmenter
from zooctl.video.grabcut import GrabCutTracker
from zooctl.video.selftrain import at_frame_size, at_working_size, track


@pytest.fixture(scope="module")
def clip():
    return moving_object_video(t=12, h=96, w=128)


def _in_thread(fn):
    out: list = []
    worker = threading.Thread(target=lambda: out.append(fn()))
    worker.start()
    worker.join()
    return out[0]


def test_both_directions_from_a_middle_seed_give_the_same_masks_every_run(clip):
    """Seeded on frame 6 of 12, the tracker runs forwards and backwards at once; the masks and the
    report do not depend on which thread runs it or on the OpenCV random state it finds."""
    frames, truth = clip
    seg = GrabCutTracker(localise=False)
    box = cues.box_of(truth[6])

    def run():
        masks = seg.segment(frames, box=box, box_frame=6)
        return np.asarray(masks, bool), dict(seg.report)

    first, report = run()
    assert report["seed_frame"] == 6 and report["seeding"][6] == "box"
    assert min(iou(m, t) for m, t in zip(first, truth)) > 0.85  # both directions tracked it
    cv2.setRNGSeed(1234)
    cv2.randu(np.zeros((64, 64), np.float32), 0, 1)  # another random state in this thread
    for again, again_report in (run(), _in_thread(run)):
        assert np.array_equal(again, first)
        assert again_report == report
    steps: list[tuple[int, int]] = []
    seg.segment(frames, box=box, box_frame=6, progress=lambda d, n: steps.append((d, n)))
    assert steps[-1] == (12, 12) and [d for d, _ in steps] == sorted(d for d, _ in steps)


@pytest.mark.parametrize("failing_direction", ["backward", "forward"])
def test_a_tracking_error_in_either_direction_is_raised_once_both_have_stopped(
    clip, monkeypatch, failing_direction
):
    frames, truth = clip
    seg = GrabCutTracker(localise=False)
    real, running = GrabCutTracker._track, set()

    def failing(self, frame, *args, **kwargs):
        on_main = threading.current_thread() is threading.main_thread()
        running.add(threading.current_thread())
        if on_main == (failing_direction == "forward"):
            raise RuntimeError("injected failure")
        return real(self, frame, *args, **kwargs)

    monkeypatch.setattr(GrabCutTracker, "_track", failing)
    with pytest.raises(RuntimeError, match="injected"):
        seg.segment(frames, box=cues.box_of(truth[6]), box_frame=6)
    assert len(running) == 2 and not any(t.is_alive() for t in running - {threading.main_thread()})


def test_looks_taken_while_tracking_give_the_masks_taken_after_it(clip):
    """`AnimalNetSegmenter.segment` takes the network's looks beside the tracker: the masks are
    those of looking after tracking, as `decide_near` alone does."""
    from zooctl.video.colour_snap import snap_video

    frames, truth = clip
    box = cues.box_of(truth[0])
    seg = AnimalNetSegmenter(feature_every=3)
    got = np.asarray(seg.segment(frames, box=box), bool)
    report = seg.report["animalnet"]
    flow, tracked = track(seg.tracker, frames, box, None, None, 0, "animalnet")
    small, prior = at_working_size(frames, tracked, flow.forward.shape[1:3])
    alone = seg.decide_near(small, prior, flow, seed_frame=seg.tracker.report["seed_frame"])
    alone = snap_video(small, alone)[0]  # step 7, after the decision, as `segment` runs it
    assert report["crop"] is None  # decided on the whole frames: the looks taken early served
    assert np.array_equal(got, np.asarray(at_frame_size(alone, frames, small, seg.edge_radius), bool))
    assert seg.report["animalnet"] == report
    assert np.array_equal(np.asarray(seg.segment(frames, box=box), bool), got)


def _write(w: VideoWriter, rec) -> VideoWriter:
    for i in range(0, len(rec.frames), 5):
        w.add_frames(rec.frames[i : i + 5])
    parts = (rec.flow_forward, rec.flow_backward, rec.occlusion_forward, rec.occlusion_backward)
    for i in range(0, len(rec.flow_forward), 4):
        w.add_flow(*(p[i : i + 4] for p in parts))
    return w


def test_writing_behind_makes_the_file_written_at_once(tmp_path):
    from test_video_store import _record, publish

    rec = _record()
    size = rec.frames.shape[1:3][::-1]
    stores = {}
    for behind in (0, 1, 10**9):  # at once; one part at a time queued; everything queued
        store = stores[behind] = VideoStore.open(tmp_path / f"s{behind}")
        w = _write(store.begin_file("bg", size, behind), rec)
        try:
            assert len(w) == 12 and w.frames.shape[0] == 12  # the frames are readable once given
            publish(store, w, rec)
        finally:
            w.discard()
    for behind in (1, 10**9):
        assert_same_video(stores[behind].get("bg"), stores[0].get("bg"))
        assert describe_h5(stores[behind].path("bg")) == describe_h5(stores[0].path("bg"))


def test_a_write_error_behind_is_raised_by_a_later_call_and_nothing_is_left(tmp_path, monkeypatch):
    """A write that fails on the writer thread (HDF5's OSError, a full disk): the caller gets one
    clear error from the next call that gives it data, or from ``finish``; ``discard`` leaves no
    temporary."""
    import h5py
    from test_video_store import _record

    rec = _record()
    real = h5py.Dataset.__setitem__

    def full_disk(self, key, value):
        if threading.current_thread() is not threading.main_thread():
            raise OSError(28, "No space left on device")
        return real(self, key, value)

    monkeypatch.setattr(h5py.Dataset, "__setitem__", full_disk)
    store = VideoStore.open(tmp_path / "s")
    w = store.begin_file("bg", rec.frames.shape[1:3][::-1], 10**9)
    with pytest.raises(StoreError, match="space"):
        _write(w, rec)
        for i, m in enumerate(rec.masks):
            w.set_mask(i, m)
        w.finish("bg", rec.fps, rec.source, rec.source_indices, rec.segmenter, rec.flow_estimator)
    w.discard()
    w.discard()
    assert store.names() == [] and not list(store.dir.iterdir())


def test_flow_left_without_occlusion_then_checked_pair_by_pair_is_the_same(clip):
    from zooctl.video.flow import DISFlow, compute_video_flow, pair_occlusion

    frames, _ = clip
    whole = compute_video_flow(DISFlow(), frames[:5])
    bare = compute_video_flow(DISFlow(), frames[:5], occlusion=False)
    assert bare.occlusion_forward is None and bare.occlusion_backward is None
    assert np.array_equal(bare.forward, whole.forward) and np.array_equal(bare.backward, whole.backward)
    for k in range(4):
        occ_f, occ_b = pair_occlusion(bare.forward[k], bare.backward[k])
        assert np.array_equal(occ_f, whole.occlusion_forward[k])
        assert np.array_equal(occ_b, whole.occlusion_backward[k])


def test_occlusion_made_by_the_writer_gives_the_file_given_the_occlusion(tmp_path):
    """`video add` leaves the flow's forward-backward check to the writer (its thread, when writing
    behind): the file is the one written from the checked arrays, at once, queued or spilled."""
    import dataclasses

    from test_video_store import _record, publish

    from zooctl.video.flow import pair_occlusion

    rec = _record()
    occ = [pair_occlusion(f, b) for f, b in zip(rec.flow_forward, rec.flow_backward)]
    rec = dataclasses.replace(
        rec, occlusion_forward=np.stack([o[0] for o in occ]), occlusion_backward=np.stack([o[1] for o in occ])
    )
    size = rec.frames.shape[1:3][::-1]
    stores = {}
    for behind in (None, 0, 1, 10**9):  # the arrays given; made at once; spilled; queued
        store = stores[behind] = VideoStore.open(tmp_path / f"s{behind}")
        w = store.begin_file("bg", size, behind or 0)
        try:
            if behind is None:
                _write(w, rec)
            else:
                for i in range(0, len(rec.frames), 5):
                    w.add_frames(rec.frames[i : i + 5])
                for i in range(0, len(rec.flow_forward), 4):
                    w.add_flow(
                        rec.flow_forward[i : i + 4], rec.flow_backward[i : i + 4], occlusion=pair_occlusion
                    )
            publish(store, w, rec)
        finally:
            w.discard()
    for behind in (0, 1, 10**9):
        assert_same_video(stores[behind].get("bg"), stores[None].get("bg"))
        assert describe_h5(stores[behind].path("bg")) == describe_h5(stores[None].path("bg"))
    with pytest.raises(ValueError, match="occlusion"):
        VideoStore.open(tmp_path / "x").begin_file("bg", size).add_flow(rec.flow_forward, rec.flow_backward)


def test_a_grabcut_mask_depends_on_its_inputs_alone(clip):
    """Each cut seeds OpenCV's random numbers (its colour models start from k-means), so the seed's
    two cuts side by side, the two tracking directions and a rerun give the masks of one thread."""
    from zooctl.video.grabcut import _grabcut

    frames, truth = clip
    trimap = np.full(truth[3].shape, cv2.GC_BGD, np.uint8)
    trimap[cv2.dilate(truth[3].astype(np.uint8), np.ones((9, 9), np.uint8)) > 0] = cv2.GC_PR_BGD
    trimap[truth[3]] = cv2.GC_PR_FGD
    first = _grabcut(frames[3], trimap, 2)
    assert iou(first, truth[3]) > 0.8
    cv2.setRNGSeed(77)
    cv2.randu(np.zeros((64, 64), np.float32), 0, 1)
    assert np.array_equal(_grabcut(frames[3], trimap, 2), first)
    assert np.array_equal(_in_thread(lambda: _grabcut(frames[3], trimap, 2)), first)


def test_the_motion_made_ahead_is_the_motion_of_the_frame_tracked(clip, monkeypatch):
    """The tracker takes each frame's motion residual from a helper thread: it is the residual of
    that frame's own flow, as when it was made in place."""
    from zooctl.video.flow import DISFlow, compute_video_flow

    frames, truth = clip
    flow = compute_video_flow(DISFlow(), frames)
    seg = GrabCutTracker(localise=False)
    real, seen = GrabCutTracker._track, []

    def checked(self, frame, bins, prior, residual, *args, **kwargs):
        i = next(k for k in range(len(frames)) if np.array_equal(frames[k], frame))
        motion = flow.forward[i] if i < len(flow.forward) else -flow.backward[i - 1]
        assert np.array_equal(residual, cues.background_motion_residual(motion))
        seen.append(i)
        return real(self, frame, bins, prior, residual, *args, **kwargs)

    monkeypatch.setattr(GrabCutTracker, "_track", checked)
    seg.segment(frames, box=cues.box_of(truth[6]), box_frame=6, flow=flow)
    assert sorted(seen) == [i for i in range(12) if i != 6]


def test_a_tracked_cut_starts_from_the_colour_models_the_last_one_left(clip):
    from zooctl.video.grabcut import _grabcut

    frames, truth = clip
    trimap = np.full(truth[4].shape, cv2.GC_BGD, np.uint8)
    trimap[cv2.dilate(truth[4].astype(np.uint8), np.ones((9, 9), np.uint8)) > 0] = cv2.GC_PR_BGD
    trimap[truth[4]] = cv2.GC_PR_FGD
    models: list = []
    cold = _grabcut(frames[4], trimap, 2, models)
    assert np.array_equal(cold, _grabcut(frames[4], trimap, 2))  # none yet: k-means, as without
    assert len(models) == 2 and all(m.shape == (1, 65) and m.any() for m in models)
    left = [m.copy() for m in models]
    warm = _grabcut(frames[4], trimap, 2, models)
    sub = trimap.copy()  # the window is the whole frame here: the same cut by hand
    cv2.grabCut(frames[4][..., ::-1].copy(), sub, None, left[0], left[1], 2, cv2.GC_EVAL)
    assert np.array_equal(warm, np.isin(sub, (cv2.GC_FGD, cv2.GC_PR_FGD)))
    assert iou(warm, truth[4]) > 0.8


def test_colour_bins_made_when_asked_for_are_the_frames_bins(clip):
    """The tracker's colour bins are made as frames are needed (a frame ahead, on its helper
    thread), in memory or in a scratch file for a lazy video: each is `cues.lab_bins` of its frame."""
    from zooctl.video.grabcut import _Bins
    from zooctl.video.scratch import ScratchArray

    frames, _ = clip
    lazy = ScratchArray(0, frames.shape[1:], np.uint8)
    for f in frames:
        lazy.append(f)
    for source in (frames, lazy):
        bins = _Bins(source)
        for i in (5, 0, 5, 11):
            assert np.array_equal(bins[i], cues.lab_bins(frames[i]))
        assert np.array_equal(_in_thread(lambda b=bins: b[7]), cues.lab_bins(frames[7]))
