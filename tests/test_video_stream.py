"""`video add` streams: memory that does not grow with the clip, the same file and masks as in
memory, the frame budget it reports, and nothing stored when it fails half-way."""

from __future__ import annotations

import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from video_helpers import assert_same_video, moving_object_video, write_png_davis

from zooctl.io.video import write_mp4
from zooctl.store.h5 import describe_h5
from zooctl.store.videos import VideoRecord, VideoStore
from zooctl.video import ingest
from zooctl.video.ingest import BUDGET_FRAMES, AddOptions, add_video, plan_frames
from zooctl.video.scratch import ScratchArray


def davis_folder(root: Path, t: int, h: int = 48, w: int = 64) -> Path:
    """A DAVIS-style folder (JPEGImages/ + Annotations/) of a t-frame synthetic clip."""
    return write_png_davis(root, *moving_object_video(t=t, h=h, w=w))


def snapshot(root: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(root)): p.read_bytes()
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.name != ".lock"
    }


def peak_bytes(store: VideoStore, folder: Path, name: str) -> int:
    """Peak bytes Python and NumPy allocate while `video add` stores ``folder``."""
    tracemalloc.start()
    try:
        add_video(store, folder, AddOptions(name=name))
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_memory_does_not_grow_with_the_clip(tmp_path):
    """Four times the frames: the same peak allocation. Holding the clip (as preprocessing once
    did, about 32 bytes a stored pixel) would add 28 MB here; streaming holds a chunk of frames."""
    h, w = 96, 128
    short = davis_folder(tmp_path / "short", 24, h, w)
    long = davis_folder(tmp_path / "long", 96, h, w)
    store = VideoStore.open(tmp_path / "store")
    add_video(store, short, AddOptions(name="warm"))  # imports and caches are not the clip's
    small, big = peak_bytes(store, short, "short"), peak_bytes(store, long, "long")
    assert big < 1.25 * small + 2**20, (small, big)
    assert big - small < (96 - 24) * h * w * 3, (small, big)  # not even the extra frames' RGB
    rec = store.get("long")
    truth = moving_object_video(t=96, h=h, w=w)[1]
    assert rec.frames.shape == (96, h, w, 3) and np.array_equal(rec.masks, truth)
    assert rec.flow_forward.shape == (95, h, w, 2) and np.abs(rec.flow_forward).max() > 0.5


def test_a_streamed_file_equals_one_written_from_memory(tmp_path):
    """`video add` streaming its frames and flow into the file gives the layout and the arrays of
    the same video stored from memory (`preprocess` + `add`)."""
    folder = davis_folder(tmp_path / "clip", 11)
    streamed, memory = VideoStore.open(tmp_path / "a"), VideoStore.open(tmp_path / "b")
    add_video(streamed, folder, AddOptions(name="v"))
    rec = ingest.preprocess(folder, AddOptions(name="v"))
    memory.add(rec)
    a, b = streamed.get("v"), memory.get("v")
    assert_same_video(a, b)
    assert describe_h5(streamed.path("v")) == describe_h5(memory.path("v"))
    same = {k: v for k, v in streamed.summary("v").items() if k != "bytes"}  # layouts differ by bytes
    assert same == {k: v for k, v in memory.summary("v").items() if k != "bytes"}


def test_a_failure_in_a_chunk_leaves_the_store_as_it_was(tmp_path, monkeypatch):
    folder = davis_folder(tmp_path / "clip", 30)
    store = VideoStore.open(tmp_path / "store")
    add_video(store, folder, AddOptions(name="keep"))
    before = snapshot(tmp_path / "store")
    from zooctl.store.videos import VideoWriter

    real, calls = VideoWriter.add_flow, []

    def failing(self, *parts):
        calls.append(len(parts[0]))
        if len(calls) == 2:  # the second chunk of frame pairs
            raise RuntimeError("injected failure")
        return real(self, *parts)

    monkeypatch.setattr(VideoWriter, "add_flow", failing)
    for opts in (AddOptions(name="new"), AddOptions(name="keep", replace=True)):
        calls.clear()
        with pytest.raises(RuntimeError, match="injected"):
            add_video(store, folder, opts)
        assert calls == [ingest.CHUNK - 1, ingest.CHUNK]  # the file was being written a chunk at a time
    assert snapshot(tmp_path / "store") == before  # no temporary, no half-written video
    assert store.names() == ["keep"] and len(store.get("keep").frames) == 30


def test_the_frame_budget_keeps_short_clips_and_says_what_it_kept_of_long_ones(tmp_path, store, capsys):
    from cli_helpers import run_inprocess

    frames, masks = moving_object_video(t=20, h=48, w=64)
    looped = np.concatenate([frames] * 18)  # 360 frames: 12 s at 30 fps
    mp4 = write_mp4(tmp_path / "long.mp4", looped, fps=30)
    mask_mp4 = write_mp4(
        tmp_path / "masks.mp4",
        np.repeat(np.concatenate([masks] * 18)[..., None] * 255, 3, -1).astype(np.uint8),
        fps=30,
    )
    plan = plan_frames(mp4, AddOptions())
    assert (plan.every, plan.end) == (2, None) and "kept 0-12 s at 15 fps of a 12 s clip" in plan.note
    assert plan_frames(mp4, AddOptions(fps=30)).note is None  # the user chose
    short = write_mp4(tmp_path / "short.mp4", frames, fps=30)
    assert plan_frames(short, AddOptions()) == ingest.FramePlan(None, None)
    r = run_inprocess(capsys, "video", "add", str(mp4), "--masks", str(mask_mp4), "-q")
    assert r.code == 0, r.err
    assert (
        "kept 0-12 s at 15 fps of a 12 s clip at 30 fps" in r.err and "--start/--end/--fps to choose" in r.err
    )
    rec = VideoStore.open(store).get("long", what=("masks",))
    assert len(rec.masks) == 180 and rec.fps == 15
    assert list(rec.source_indices[:3]) == [0, 2, 4]


def test_a_long_clip_keeps_its_first_seconds(tmp_path):
    frames, _ = moving_object_video(t=10, h=32, w=32)
    mp4 = write_mp4(tmp_path / "minute.mp4", np.concatenate([frames] * 75), fps=30)  # 25 s
    plan = plan_frames(mp4, AddOptions())
    assert (plan.every, plan.end) == (2, 20.0) and plan.note.startswith(
        "kept 0-20 s at 15 fps of a 25 s clip"
    )
    later = plan_frames(mp4, AddOptions(start=10))
    assert (later.every, later.end) == (2, None)  # 15 s from 10 s: 225 frames at 15 fps
    assert BUDGET_FRAMES == 300


def test_grabcut_gives_the_same_masks_from_scratch_files_as_in_memory():
    """The tracker reads a stored video's frames lazily and keeps its working set in scratch
    files: the masks are those it makes from arrays in memory."""
    from test_video_localise import RedLocaliser

    from zooctl.video import cues
    from zooctl.video.grabcut import GrabCutTracker

    frames, truth = moving_object_video(t=12, h=96, w=160)
    lazy = ScratchArray(len(frames), frames.shape[1:], np.uint8)
    for i, f in enumerate(frames):
        lazy[i] = f
    for box in (None, cues.box_of(truth[4])):
        out = []
        for given in (frames, lazy):
            seg = GrabCutTracker(work_size=120, key_every=4)
            seg._loc = RedLocaliser()
            out.append((np.asarray(seg.segment(given, box=box, box_frame=4 if box else 0)), seg.report))
        assert np.array_equal(out[0][0], out[1][0]) and out[0][1] == out[1][1]
        assert out[0][0].shape == truth.shape and out[0][0].any()


def test_scratch_arrays_read_back_what_was_written():
    a = ScratchArray(3, (4, 5), np.float32)
    a[1] = np.arange(20, dtype=np.float32).reshape(4, 5)
    assert not a[0].any() and np.array_equal(a[1], np.arange(20).reshape(4, 5))
    a.append(np.ones((4, 5)))
    assert a.shape == (4, 4, 5) and a[-1].sum() == 20 and np.asarray(a).shape == (4, 4, 5)
    assert np.array_equal(a[1:3], np.stack([a[1], a[2]]))
    with pytest.raises(IndexError):
        a[4]
    a.close()


def test_records_stored_from_memory_still_validate(tmp_path):
    frames, masks = moving_object_video(t=3, h=16, w=16)
    z = np.zeros((2, 16, 16, 2), np.float32)
    rec = VideoRecord(
        "m",
        frames,
        masks,
        z,
        z,
        z[..., 0] > 0,
        z[..., 0] > 0,
        24.0,
        {"path": "x", "kind": "images", "sha256": "0"},
        np.arange(3),
    )
    VideoStore.open(tmp_path).add(rec)
    assert VideoStore.open(tmp_path).get("m").frames.shape == (3, 16, 16, 3)


def test_max_memory_bounds_the_frame_size_not_the_length(tmp_path):
    from zooctl.errors import InputError

    folder = davis_folder(tmp_path / "clip", 96, 96, 128)
    store = VideoStore.open(tmp_path / "store")
    # all 96 frames at 32 bytes a pixel would need 0.038 GB; a chunk of them needs 0.004 GB
    add_video(store, folder, AddOptions(name="long", max_memory_gb=0.02))
    assert store.summary("long")["frames"] == 96
    with pytest.raises(InputError, match="frames of 128x96 need about .* GB to preprocess"):
        add_video(store, folder, AddOptions(name="big", max_memory_gb=0.002))


def test_video_show_reads_a_stored_video_a_frame_at_a_time(tmp_path):
    """`video show`'s statistics from the file, frame by frame, are those of the video in memory."""
    from zooctl.store.h5 import read_h5
    from zooctl.video.stats import stored_video_stats, video_stats

    store = VideoStore.open(tmp_path / "store")
    add_video(store, davis_folder(tmp_path / "clip", 11), AddOptions(name="v"))
    whole = video_stats(store.get("v"))
    streamed = read_h5(store.path("v"), "video", "", stored_video_stats)
    fw, fs = whole.pop("flow"), streamed.pop("flow")
    assert streamed == whole
    assert fs["per_frame_mean_magnitude"] == fw["per_frame_mean_magnitude"]
    for key in ("mean_magnitude", "max_magnitude", "occluded_fraction"):
        assert fs[key] == pytest.approx(fw[key], rel=1e-5), key
    assert abs(fs["p99_magnitude"] - fw["p99_magnitude"]) <= 2e-3
