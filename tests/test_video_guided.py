"""Masks brought from the working size to the frame's size along the frame's colour edges."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from zooctl.errors import UsageError
from zooctl.video.guided import guided_upsample
from zooctl.video.scratch import ScratchArray
from zooctl.video.selftrain import at_frame_size


def _scene(seed: int = 0, size: tuple[int, int] = (240, 320)):
    """A textured background and an animal-like shape (a body and four thin legs) of another
    colour, with its truth: ((H, W, 3) uint8 frame, (H, W) bool truth)."""
    h, w = size
    rng = np.random.default_rng(seed)
    frame = np.clip(rng.normal(90, 12, (h, w, 3)), 0, 255).astype(np.uint8)
    truth = np.zeros((h, w), np.uint8)
    cv2.ellipse(truth, (w // 2, h // 2 - 20), (70, 35), 0, 0, 360, 1, -1)
    for x in (w // 2 - 55, w // 2 - 35, w // 2 + 30, w // 2 + 50):
        cv2.rectangle(truth, (x, h // 2), (x + 6, h // 2 + 60), 1, -1)
    frame[truth > 0] = np.clip(rng.normal(200, 12, (int(truth.sum()), 3)), 0, 255).astype(np.uint8)
    return frame, truth > 0


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


def test_the_outline_follows_the_frame_where_a_linear_upsample_blurs_it():
    frame, truth = _scene()
    h, w = truth.shape
    small = cv2.resize(frame, (w // 4, h // 4), interpolation=cv2.INTER_AREA)
    coarse = cv2.resize(truth.astype(np.uint8), (w // 4, h // 4), interpolation=cv2.INTER_AREA) > 0
    # decided at a quarter of the size and dilated by a cell, as a mask decided on a grid is
    coarse = cv2.dilate(coarse.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    linear = cv2.resize(coarse.astype(np.float32), (w, h), interpolation=cv2.INTER_LINEAR) > 0.5
    guided = guided_upsample(coarse, small, frame, radius=0.03)
    assert guided.shape == truth.shape and guided.dtype == bool
    assert _iou(guided, truth) > _iou(linear, truth) + 0.1
    assert _iou(guided, truth) > 0.85


def test_an_empty_mask_stays_empty_and_a_speck_keeps_a_mask():
    frame, _ = _scene()
    h, w = frame.shape[:2]
    small = cv2.resize(frame, (w // 2, h // 2), interpolation=cv2.INTER_AREA)
    assert not guided_upsample(np.zeros((h // 2, w // 2), bool), small, frame).any()
    speck = np.zeros((h // 2, w // 2), bool)
    speck[5, 5] = True  # on the background's texture: the window would smooth it away
    assert guided_upsample(speck, small, frame, radius=0.05).any()


def test_scratch_masks_upsampled_lazily_equal_those_in_memory(tmp_path):
    frames = np.stack([_scene(seed)[0] for seed in range(3)])
    t, h, w = frames.shape[:3]
    small = np.stack([cv2.resize(f, (w // 2, h // 2), interpolation=cv2.INTER_AREA) for f in frames])
    masks = np.stack([cv2.resize(_scene(s)[1].astype(np.uint8), (w // 2, h // 2)) > 0 for s in range(3)])
    masks[1] = False
    in_memory = at_frame_size(masks, frames, small, 0.02)
    with ScratchArray(t, (h, w, 3), np.uint8) as on_disk:
        for i in range(t):
            on_disk[i] = frames[i]
        lazy = at_frame_size(masks, on_disk, small, 0.02)
        assert lazy.shape == in_memory.shape
        assert np.array_equal(np.asarray(lazy), in_memory)
    assert not in_memory[1].any()
    linear = at_frame_size(masks, frames)
    assert not np.array_equal(linear, in_memory)


def test_a_bad_edge_window_is_refused():
    from zooctl.video.animalnet import AnimalNetSegmenter

    with pytest.raises(UsageError, match="edge_radius"):
        AnimalNetSegmenter(edge_radius=-0.1)
    with pytest.raises(UsageError, match="edge_eps"):
        AnimalNetSegmenter(edge_eps=0)
