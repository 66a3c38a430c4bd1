"""Re-segmenting with a shape prior (`zooctl.video.shape_prior`) on a drawn frame."""

from __future__ import annotations

import cv2
import numpy as np

from zooctl.video.shape_prior import PriorOptions, refine_frame, refine_masks, trimap


def _scene(seed: int = 0):
    """A brown animal (body and four thin legs) on green grass, a white wake behind it; the
    colour mask (body + wake, no legs) and the prior (body + legs, no wake)."""
    rng = np.random.default_rng(seed)
    h, w = 240, 320
    frame = np.empty((h, w, 3), np.uint8)
    frame[:] = (60, 140, 50)
    body = np.zeros((h, w), np.uint8)
    cv2.ellipse(body, (160, 110), (70, 32), 0, 0, 360, 1, -1)
    legs = np.zeros((h, w), np.uint8)
    for x in (110, 130, 190, 210):
        cv2.rectangle(legs, (x, 130), (x + 5, 190), 1, -1)
    wake = np.zeros((h, w), np.uint8)
    cv2.ellipse(wake, (255, 118), (40, 14), 0, 0, 360, 1, -1)
    wake &= 1 - body
    body, legs, wake = body.astype(bool), legs.astype(bool) & ~body.astype(bool), wake.astype(bool)
    frame[wake] = (235, 240, 245)
    frame[body | legs] = (120, 75, 40)
    noise = rng.normal(0, 6, frame.shape)
    frame = np.clip(frame + noise, 0, 255).astype(np.uint8)
    colour_mask = body | wake
    prior = body | legs
    return frame, colour_mask, prior, body, legs, wake


def test_trimap_is_sure_only_deep_inside_both_and_far_outside():
    frame, mask, prior, body, legs, wake = _scene()
    t = trimap(mask, prior)
    assert (t[legs] == cv2.GC_PR_FGD).all()  # thin: never sure
    assert (t[wake & ~prior] != cv2.GC_FGD).all()
    assert (t[body] == cv2.GC_FGD).any()
    assert t[0, 0] == cv2.GC_BGD


def test_refined_mask_recovers_legs_and_drops_wake():
    frame, mask, prior, body, legs, wake = _scene()
    out = refine_frame(frame, mask, prior)
    assert out[legs].mean() > 0.9, "the legs the prior covers come back"
    assert out[wake].mean() < 0.1, "the wake the prior leaves out goes"
    assert out[body].mean() > 0.95
    truth = body | legs
    j_before = (mask & truth).sum() / (mask | truth).sum()
    j_after = (out & truth).sum() / (out | truth).sum()
    assert j_after > j_before + 0.1


def test_no_prior_keeps_the_mask_and_batches_match_frames():
    frame, mask, prior, *_ = _scene()
    frames = np.stack([frame, frame])
    masks = np.stack([mask, mask])
    priors = np.stack([prior, np.zeros_like(prior)])
    out = refine_masks(frames, masks, priors, PriorOptions())
    assert out.shape == masks.shape and out.dtype == bool
    assert np.array_equal(out[1], mask)
    assert np.array_equal(out[0], refine_frame(frame, mask, prior))  # deterministic, frame by frame
