"""Bounded and checked `video add` inputs (issue 18, items 6-10): mask counts, photos given as
masks, --max-size 0, specks of masks, and the decoded-size budget."""

from __future__ import annotations

import numpy as np
import pytest
from cli_helpers import run_inprocess
from PIL import Image
from video_helpers import moving_object_video

from zooctl.errors import InputError, UsageError
from zooctl.io.video import write_mp4
from zooctl.store.videos import VideoStore
from zooctl.video.decode import decode
from zooctl.video.ingest import AddOptions, add_video


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    """An 8-frame image folder, its true masks, and the frames as an H.264 file."""
    frames, masks = moving_object_video(t=8, h=96, w=128)
    root = tmp_path_factory.mktemp("lim")
    (root / "frames").mkdir()
    for i, f in enumerate(frames):
        Image.fromarray(f).save(root / "frames" / f"{i:05d}.png")
    write_mp4(root / "frames.mp4", frames, fps=24, quality=12)
    return root, frames, masks


def write_masks(folder, masks):
    folder.mkdir(parents=True, exist_ok=True)
    for i, m in enumerate(masks):
        Image.fromarray(m.astype(np.uint8) * 255).save(folder / f"{i:05d}.png")
    return folder


def add(store, path, **kw):
    return add_video(VideoStore.open(store), path, AddOptions(**kw))


def test_more_masks_than_frames_is_an_error(store, video, tmp_path):
    root, _, masks = video
    extra = write_masks(tmp_path / "extra", np.concatenate([masks, masks[:2]]))
    with pytest.raises(InputError, match="10 masks .* 8 frames"):
        add(store, root / "frames", name="a", masks=extra)
    # the source's own count stays accepted when only some of its frames are stored
    summary = add(store, root / "frames", name="b", masks=write_masks(tmp_path / "ok", masks), max_frames=5)
    assert summary["frames"] == 5
    assert VideoStore.open(store).names() == ["b"]


def test_rgb_frames_or_video_as_masks_are_refused(store, video):
    root, _, _ = video
    with pytest.raises(InputError, match="is not a mask: it has the many colours of a photo"):
        add(store, root / "frames", name="a", masks=root / "frames")
    with pytest.raises(InputError, match="is not a mask"):
        add(store, root / "frames", name="a", masks=root / "frames.mp4")
    assert VideoStore.open(store).names() == []


def test_binary_mask_video_is_accepted(store, video, tmp_path):
    root, _, masks = video
    mv = write_mp4(tmp_path / "m.mp4", np.repeat(masks[..., None], 3, -1).astype(np.uint8) * 255, fps=24)
    assert add(store, root / "frames.mp4", name="a", masks=mv)["frames"] == 8


def test_max_size_zero_keeps_the_size(store, tmp_path, capsys):
    frames, masks = moving_object_video(t=3, h=480, w=960)
    folder = tmp_path / "big"
    (folder / "JPEGImages").mkdir(parents=True)
    write_masks(folder / "Annotations", masks)
    for i, f in enumerate(frames):
        Image.fromarray(f).save(folder / "JPEGImages" / f"{i:05d}.jpg")
    r = run_inprocess(capsys, "video", "add", str(folder), "--max-size", "0", "-q", "--json")
    assert r.code == 0, r.err
    assert VideoStore.open(store).summary("big")["width"] == 960
    r = run_inprocess(capsys, "video", "add", str(folder), "--name", "small", "-q")
    assert r.code == 0 and VideoStore.open(store).summary("small")["width"] == 854


def test_specks_of_masks_are_refused_and_empty_frames_reported(store, video, tmp_path):
    root, _, masks = video
    specks = np.zeros_like(masks)
    specks[:, 40:42, 60:62] = True  # 4 pixels of 12,288
    with pytest.raises(InputError, match="masks cover almost nothing"):
        add(store, root / "frames", name="a", masks=write_masks(tmp_path / "specks", specks))
    some_empty = masks.copy()
    some_empty[[2, 5]] = False
    summary = add(store, root / "frames", name="b", masks=write_masks(tmp_path / "holes", some_empty))
    assert summary["empty_masks"] == 2
    assert VideoStore.open(store).get("b", what=()).segmenter["empty_frames"] == [2, 5]
    with pytest.raises(InputError, match="no animal in any of the 8 frames"):
        add(store, root / "frames", name="c", masks=write_masks(tmp_path / "none", np.zeros_like(masks)))


def test_decoded_size_is_bounded(video, capsys, store):
    root, _, _ = video
    # 8 frames of 128x96 need 8 * 12288 * 32 bytes = 3.1 MB
    with pytest.raises(InputError, match=r"need about .* GB to preprocess, over the --max-memory limit"):
        decode(root / "frames", max_memory_gb=0.003)
    with pytest.raises(InputError, match="--max-memory limit"):
        decode(root / "frames.mp4", max_memory_gb=0.003)
    assert len(decode(root / "frames.mp4", max_memory_gb=0.004).frames) == 8
    with pytest.raises(UsageError, match="must be positive"):
        decode(root / "frames", max_memory_gb=0)
    r = run_inprocess(capsys, "video", "add", str(root / "frames.mp4"), "--max-memory", "0.001", "-q")
    assert r.code == 2 and "raise --max-memory" in r.err and "Traceback" not in r.err
