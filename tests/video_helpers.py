"""Synthetic videos for the video tests: a textured background panning, an object moving over it."""

from __future__ import annotations

import numpy as np


def texture(h: int, w: int, seed: int = 0) -> np.ndarray:
    """(h, w, 3) uint8 smooth random texture (flow needs structure to lock onto)."""
    import cv2

    rng = np.random.default_rng(seed)
    small = rng.integers(0, 256, (h // 8 + 2, w // 8 + 2, 3), dtype=np.uint8)
    big = cv2.resize(small, (w + 16, h + 16), interpolation=cv2.INTER_CUBIC)
    return big[:h, :w]


def moving_object_video(
    t: int = 8, h: int = 96, w: int = 128, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """A red-orange ellipse moving right over a grey-green background panning left.

    Returns frames (t, h, w, 3) uint8 and the true masks (t, h, w) bool.
    """
    import cv2

    bg = texture(h, w + 4 * t, seed)
    bg = (bg * 0.5 + np.array([60, 90, 60])).astype(np.uint8)  # muted greens
    obj_tex = (texture(h, w, seed + 1) * 0.25 + np.array([190, 70, 30])).astype(np.uint8)  # reds
    frames = np.empty((t, h, w, 3), np.uint8)
    masks = np.zeros((t, h, w), bool)
    for i in range(t):
        f = np.ascontiguousarray(bg[:, 2 * i : 2 * i + w])
        m = np.zeros((h, w), np.uint8)
        cv2.ellipse(m, (w // 3 + 3 * i, h // 2), (w // 6, h // 5), 0, 0, 360, 1, -1)
        f[m > 0] = obj_tex[m > 0]
        frames[i], masks[i] = f, m > 0
    return frames, masks


def iou(a: np.ndarray, b: np.ndarray) -> float:
    u = np.logical_or(a, b).sum()
    return 1.0 if u == 0 else float(np.logical_and(a, b).sum() / u)


def stored_masked_video(tmp_path, name: str = "seq"):
    """A DAVIS-style folder of a 6-frame masked video at ``tmp_path/name`` and a store at
    ``tmp_path/store`` holding it under ``name``: (store root, folder)."""
    from zooctl.store.videos import VideoStore
    from zooctl.video.ingest import AddOptions, add_video

    frames, masks = moving_object_video(t=6, h=96, w=128)
    folder = write_png_davis(tmp_path / name, frames, masks)
    root = tmp_path / "store"
    add_video(VideoStore.open(root), folder, AddOptions(name=name))
    return root, folder


def write_pngs(folder, images: np.ndarray):
    """Images (T, H, W, 3) uint8 or masks (T, H, W) bool as numbered lossless PNGs in ``folder``
    (made, as a folder of frames `video add` reads); returns ``folder``."""
    from PIL import Image

    folder.mkdir(parents=True)
    for i, img in enumerate(images):
        Image.fromarray(img.astype(np.uint8) * 255 if img.dtype == bool else img).save(
            folder / f"{i:05d}.png"
        )
    return folder


def write_png_davis(folder, frames: np.ndarray, masks: np.ndarray):
    """Frames (T, H, W, 3) uint8 and masks (T, H, W) bool as a DAVIS-style folder of lossless PNGs
    (JPEGImages/, Annotations/); returns ``folder``."""
    if len(frames) != len(masks):
        raise ValueError(f"{len(frames)} frames but {len(masks)} masks")
    write_pngs(folder / "JPEGImages", frames)
    write_pngs(folder / "Annotations", np.asarray(masks, bool))
    return folder


def synthetic_video(name: str, t: int = 4, h: int = 24, w: int = 32, seed: int = 0):
    """A small stored-video record of random frames and flow with a box mask (no decoding)."""
    from zooctl.store.videos import VideoRecord

    rng = np.random.default_rng(seed)
    masks = np.zeros((t, h, w), bool)
    masks[:, 5:15, 8:20] = True
    return VideoRecord(
        name=name,
        frames=rng.integers(0, 255, (t, h, w, 3), dtype=np.uint8),
        masks=masks,
        flow_forward=rng.normal(size=(t - 1, h, w, 2)).astype(np.float32),
        flow_backward=rng.normal(size=(t - 1, h, w, 2)).astype(np.float32),
        occlusion_forward=np.zeros((t - 1, h, w), bool),
        occlusion_backward=np.zeros((t - 1, h, w), bool),
        fps=30.0,
        source={"path": "syn", "kind": "images", "sha256": "0" * 64},
        source_indices=np.arange(t),
        segmenter={"name": "masks"},
        flow_estimator={"name": "dis"},
    )


VIDEO_ARRAYS = ("frames", "masks", "flow_forward", "flow_backward", "occlusion_forward", "occlusion_backward")


def assert_same_video(a, b) -> None:
    """Two stored-video records hold the same arrays, source, segmenter and frame rate."""
    for key in VIDEO_ARRAYS:
        assert np.array_equal(getattr(a, key), getattr(b, key)), key
    assert a.source == b.source and a.segmenter == b.segmenter and a.fps == b.fps
