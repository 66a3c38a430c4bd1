"""Decoding video files, image folders and DAVIS folders; the bad inputs the issue lists."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import VIDEOS_DIR, needs_shared_videos
from PIL import Image
from video_helpers import moving_object_video

from zooctl.errors import InputError, UsageError
from zooctl.io.video import write_mp4
from zooctl.video.decode import decode, image_files, scaled_size


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    frames, masks = moving_object_video(t=12, h=96, w=128)
    path = tmp_path_factory.mktemp("clip") / "clip.mp4"
    write_mp4(path, frames, fps=24, quality=12)
    return path, frames, masks


def test_decode_mp4_matches_written_frames(clip):
    path, frames, _ = clip
    dv = decode(path)
    assert dv.kind == "file" and dv.fps == pytest.approx(24)
    assert dv.frames.shape == frames.shape and dv.frames.dtype == np.uint8
    assert np.abs(dv.frames.astype(int) - frames.astype(int)).mean() < 6  # H.264 at CRF 12
    assert dv.original_size == (128, 96) and len(dv.sha256) == 64
    assert dv.source_indices.tolist() == list(range(12))


def test_decode_window_fps_and_max_frames(clip):
    path, _, _ = clip
    half = decode(path, fps=12)
    assert half.fps == 12 and len(half.frames) == 6
    window = decode(path, start=0.25, end=0.375)  # frames 6, 7, 8 at 24 fps
    assert len(window.frames) == 3 and window.source_indices[0] == 6
    assert len(decode(path, max_frames=4).frames) == 4


def test_large_video_is_downscaled_to_max_size(tmp_path):
    rng = np.random.default_rng(0)
    big = rng.integers(0, 255, (2, 2160, 3840, 3), dtype=np.uint8)  # a 4K clip, 2 frames
    path = write_mp4(tmp_path / "4k.mp4", big, fps=30, quality=35)
    dv = decode(path)
    assert dv.frames.shape == (2, 480, 854, 3) and dv.original_size == (3840, 2160)
    assert decode(path, max_size=256).frames.shape[1:3] == (144, 256)
    assert scaled_size(3840, 2160, None) == (3840, 2160)


def test_image_folder_natural_order_and_window(tmp_path):
    frames, _ = moving_object_video(t=11, h=48, w=64)
    for i, f in enumerate(frames):
        Image.fromarray(f).save(tmp_path / f"f{i}.png")  # f10 must come after f9
    assert [p.name for p in image_files(tmp_path)][-2:] == ["f9.png", "f10.png"]
    dv = decode(tmp_path, fps=10, start=0.5)
    assert dv.kind == "images" and dv.fps == 10 and dv.source_indices.tolist() == [5, 6, 7, 8, 9, 10]
    assert np.array_equal(dv.frames[0], frames[5])


def test_one_image_is_a_one_frame_video(tmp_path):
    frames, _ = moving_object_video(t=3, h=48, w=64)
    for i, f in enumerate(frames):  # siblings in the same folder are not frames of the photo
        Image.fromarray(f).save(tmp_path / f"f{i}.png")
    dv = decode(tmp_path / "f1.png")
    assert dv.kind == "images" and dv.frames.shape == (1, 48, 64, 3) and dv.source_indices.tolist() == [0]
    assert np.array_equal(dv.frames[0], frames[1]) and dv.image_files == [tmp_path / "f1.png"]
    (tmp_path / "bad.jpg").write_bytes(b"not a jpeg")
    with pytest.raises(InputError, match="not a readable image"):
        decode(tmp_path / "bad.jpg")


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda p: p.with_suffix(".mp4").write_bytes(b""), "is empty"),
        (
            lambda p: p.with_suffix(".mp4").write_bytes(b"\x00\x00\x00\x18ftypmp42" + b"garbage" * 500),
            "not a readable video",
        ),
        (lambda p: p.with_suffix(".txt").write_text("hello"), "not a video file"),
        (lambda p: p.mkdir(), "holds no images"),
    ],
    ids=["empty", "corrupt", "wrong-suffix", "no-images"],
)
def test_bad_inputs_raise_one_clear_error(tmp_path, make, message):
    target = tmp_path / "bad"
    make(target)
    path = next(tmp_path.iterdir())
    with pytest.raises(InputError, match=message):
        decode(path)


def test_bad_options(clip):
    path, _, _ = clip
    with pytest.raises(UsageError, match="not after"):
        decode(path, start=2, end=1)
    with pytest.raises(UsageError, match="too small"):
        decode(path, max_size=4)
    with pytest.raises(InputError, match="no video frames"):
        decode(path, start=100)
    with pytest.raises(InputError, match="does not exist"):
        decode(path.with_name("missing.mp4"))


def test_mixed_image_sizes_rejected(tmp_path):
    Image.new("RGB", (64, 48)).save(tmp_path / "0.png")
    Image.new("RGB", (32, 48)).save(tmp_path / "1.png")
    with pytest.raises(InputError, match="the first image is 64x48"):
        decode(tmp_path)


@needs_shared_videos
def test_davis_folder_has_annotations():
    dv = decode(VIDEOS_DIR / "cows", max_frames=3, max_size=256)
    assert dv.kind == "davis" and dv.annotations == VIDEOS_DIR / "cows" / "Annotations"
    assert dv.frames.shape == (3, 144, 256, 3) and dv.original_size == (854, 480)
