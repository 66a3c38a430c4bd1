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
    from PIL import Image

    from zooctl.store.videos import VideoStore
    from zooctl.video.ingest import AddOptions, add_video

    frames, masks = moving_object_video(t=6, h=96, w=128)
    folder = tmp_path / name
    (folder / "JPEGImages").mkdir(parents=True)
    (folder / "Annotations").mkdir()
    for i, (f, m) in enumerate(zip(frames, masks)):
        Image.fromarray(f).save(folder / "JPEGImages" / f"{i:05d}.png")
        Image.fromarray(m.astype(np.uint8) * 255).save(folder / "Annotations" / f"{i:05d}.png")
    root = tmp_path / "store"
    add_video(VideoStore.open(root), folder, AddOptions(name=name))
    return root, folder
