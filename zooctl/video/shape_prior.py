"""Re-segmenting frames with a shape prior: a fitted character's silhouette seen through its camera.

A colour model drops thin parts whose pixels it is unsure of (legs, tails, necks) and keeps what
moves and looks like the animal but is not it (a rider, a wake, a reflection). A fitted animal's
reprojection knows the animal's shape: where it and the mask agree, deep inside both, is surely
the animal; far outside both is surely not; everything between is left to GrabCut, started with
the prior's side of the question (probably the animal inside the prior, probably background
outside it) and its colour models learnt from that start. So a leg the prior covers and whose
colours are the animal's comes back, and a wake the prior leaves out, coloured unlike the animal,
goes.

The radii are fixed beforehand from the masks' own size, not tuned on any video: the sure core
is what stays after eroding by ``core`` times the animal's size (the square root of the union's
area), so a leg thinner than twice that is never sure either way; the band GrabCut may relabel
reaches ``band`` times the size past the union (a fitted silhouette is off by a few per cent of
the animal's size where it is off at all).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from . import cues
from .grabcut import _grabcut


@dataclass(frozen=True)
class PriorOptions:
    """``core``: erosion radius of the sure foreground, ``band``: dilation radius of what may
    change, each as a fraction of the animal's size (module docstring). ``iterations``: GrabCut
    iterations per frame."""

    core: float = 0.05
    band: float = 0.1
    iterations: int = 3


def trimap(mask: np.ndarray, prior: np.ndarray, opts: PriorOptions = PriorOptions()) -> np.ndarray:
    """GrabCut labels (H, W) uint8 for one frame from its mask and the prior, both (H, W) bool:
    ``GC_FGD`` where both agree after eroding, ``GC_BGD`` past the band around their union,
    ``GC_PR_FGD`` inside the prior, ``GC_PR_BGD`` elsewhere."""
    union = mask | prior
    size = float(np.sqrt(np.count_nonzero(union)))
    out = np.full(mask.shape, cv2.GC_BGD, np.uint8)
    if size == 0:
        return out
    near = cv2.dilate(union.astype(np.uint8), cues.disk(max(1, round(opts.band * size)))).astype(bool)
    out[near] = cv2.GC_PR_BGD
    out[prior] = cv2.GC_PR_FGD
    both = (mask & prior).astype(np.uint8)
    core = cv2.erode(both, cues.disk(max(1, round(opts.core * size)))).astype(bool)
    out[core] = cv2.GC_FGD
    return out


def refine_frame(
    frame: np.ndarray, mask: np.ndarray, prior: np.ndarray, opts: PriorOptions = PriorOptions()
) -> np.ndarray:
    """One frame re-segmented: frame (H, W, 3) uint8 RGB, mask and prior (H, W) bool -> (H, W) bool.

    Without a prior (the fitted animal is out of view) the mask is kept as it is; without a mask
    the prior alone starts GrabCut (the colour model lost the animal, the fit did not)."""
    mask, prior = np.asarray(mask, bool), np.asarray(prior, bool)
    if not prior.any():
        return mask.copy()
    labels = trimap(mask, prior, opts)
    cv2.setRNGSeed(0)  # GrabCut's GMMs start from k-means: the same frame gives the same mask
    out = _grabcut(np.asarray(frame, np.uint8), labels, opts.iterations)
    if not out.any():
        return out
    # the animal is one body: pieces away from the prior (a wake, another animal) do not count
    return cues.fill_holes(cues.largest_components(out, reference=prior))


def refine_masks(
    frames, masks: np.ndarray, priors: np.ndarray, opts: PriorOptions = PriorOptions(), progress=None
) -> np.ndarray:
    """(T, H, W) bool masks re-segmented with the prior: frames (T, H, W, 3) uint8 RGB (an array,
    or anything indexed a frame at a time), masks and priors (T, H, W) bool. ``progress(i)`` is
    called after each frame."""
    masks, priors = np.asarray(masks, bool), np.asarray(priors, bool)
    if masks.shape != priors.shape or tuple(frames.shape[:3]) != masks.shape:
        raise ValueError(f"frames {frames.shape[:3]}, masks {masks.shape} and priors {priors.shape} differ")
    out = np.zeros_like(masks)
    for i in range(len(masks)):
        out[i] = refine_frame(frames[i], masks[i], priors[i], opts)
        if progress is not None:
            progress(i)
    return out


__all__ = ["PriorOptions", "refine_frame", "refine_masks", "trimap"]
