"""The masks snapped to the animal's colours: a last GrabCut per frame, kept for a video only where
it makes the animal's colours stand apart from its surroundings.

A tracker's and a learned relabelling's masks can take in a blob of background beside the animal
(grass up to the horizon beside a grey dolphin, the ground a fox has just crossed): the motion and
the coarse network features call it animal, the colours do not. `snap_frame` runs GrabCut seeded by
the mask itself (inside: probably the animal; a ring around it: probably background; beyond: sure
background), so each pixel goes to the colour model it fits. On real footage the ground is often
the animal's colour and the snap then takes in ground or drops blurred legs, so a video is snapped
only when the snap separates the mask's colours from its ring's more than the masks did: the median
over every third frame of `separation` after minus before exceeds ``min_gain``
(`snap_video`). The threshold was chosen on the seven shared DAVIS videos and two 28-video
`zooctl bench make` sets, the leave-one-video-out figures beside it (`bench/colour_snap.py`;
BENCHMARKS.md, "Masks snapped to the animal's colours").
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from contextlib import nullcontext

import cv2
import numpy as np

from .flow import flow_workers
from .scratch import working

BAND = 0.15  # the ring of probable background, a fraction of the mask's square-root area
ITERATIONS = 3
# the median separation gain over a video's frames above which its masks are snapped
MIN_GAIN = 0.005
LOOK_EVERY = 3  # the gate looks at every third frame, as the network does (`animalnet`)
_MIN_PIXELS = 16


def _disc(radius: int) -> np.ndarray:
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))


def ring_width(mask: np.ndarray, band: float = BAND) -> int:
    """The ring's width in pixels for an (H, W) bool mask: ``band`` times the square root of its area."""
    return max(int(round(band * np.sqrt(max(int(mask.sum()), 1)))), 2)


def snap_frame(
    frame: np.ndarray, mask: np.ndarray, band: float = BAND, iterations: int = ITERATIONS
) -> np.ndarray:
    """(H, W, 3) uint8 RGB frame and (H, W) bool mask -> (H, W) bool mask after GrabCut seeded by it.

    Inside the mask: probably the animal; a ring ``band`` x sqrt(area) wide around it: probably
    background; beyond: background. GrabCut runs on the mask's box grown by three rings (the rest
    stays background). A mask under 16 pixels, or one whose ring reaches every side of the frame
    (no sure background to learn from), comes back unchanged."""
    m = np.asarray(mask, bool)
    if m.sum() < _MIN_PIXELS:
        return m
    h, w = m.shape
    r = ring_width(m, band)
    ys, xs = np.nonzero(m)
    x0, x1 = max(int(xs.min()) - 3 * r, 0), min(int(xs.max()) + 3 * r + 1, w)
    y0, y1 = max(int(ys.min()) - 3 * r, 0), min(int(ys.max()) + 3 * r + 1, h)
    crop = m[y0:y1, x0:x1].astype(np.uint8)
    near = cv2.dilate(crop, _disc(r)) > 0
    labels = np.full(crop.shape, cv2.GC_BGD, np.uint8)
    labels[near] = cv2.GC_PR_BGD
    labels[crop > 0] = cv2.GC_PR_FGD
    if not (labels == cv2.GC_BGD).any():
        return m
    bgd, fgd = np.zeros((1, 65)), np.zeros((1, 65))
    cv2.setRNGSeed(0)  # GrabCut's k-means draws from this thread's generator: the same cut on any thread
    bgr = cv2.cvtColor(np.ascontiguousarray(frame[y0:y1, x0:x1]), cv2.COLOR_RGB2BGR)
    cv2.grabCut(bgr, labels, None, bgd, fgd, iterations, cv2.GC_INIT_WITH_MASK)
    out = np.zeros_like(m)
    out[y0:y1, x0:x1] = (labels == cv2.GC_FGD) | (labels == cv2.GC_PR_FGD)
    return out


def _histogram(lab: np.ndarray, where: np.ndarray) -> np.ndarray:
    q = lab[where].astype(np.int32) // 32  # 8 levels a channel
    h = np.bincount((q[:, 0] * 8 + q[:, 1]) * 8 + q[:, 2], minlength=512).astype(np.float64)
    return h / max(h.sum(), 1.0)


def separation(lab: np.ndarray, mask: np.ndarray, ring: int) -> float:
    """1 - the Bhattacharyya coefficient of the colours inside ``mask`` and in the ring ``ring``
    pixels wide outside it, for an (H, W, 3) uint8 Lab frame: 0 the same colours, 1 none shared.
    NaN for a mask or ring under 16 pixels."""
    m = np.asarray(mask, bool)
    around = (cv2.dilate(m.astype(np.uint8), _disc(ring)) > 0) & ~m
    if m.sum() < _MIN_PIXELS or around.sum() < _MIN_PIXELS:
        return float("nan")
    return 1.0 - float(np.sum(np.sqrt(_histogram(lab, m) * _histogram(lab, around))))


def snap_video(frames, masks, min_gain: float = MIN_GAIN, every: int = LOOK_EVERY) -> tuple[object, dict]:
    """(T, h, w, 3) uint8 RGB frames and (T, h, w) bool masks -> (masks, report).

    Every ``every``-th frame (and the last) is snapped first (`snap_frame`, frames side by side on
    `flow.flow_workers` threads) and its separation gain measured: `separation` of the snapped mask
    minus that of the given one, each with the given mask's ring width (a frame the cut leaves empty
    keeps its mask and has no gain). When the median gain exceeds
    ``min_gain`` the other frames are snapped too and the snapped masks replace the given ones, all
    of them, in memory or, for frames that wait in scratch files (a long video), in a scratch array;
    else the given masks come back (a video left as it was costs a third of the frames' cuts).
    ``report``: ``separation_gain`` (the median, None when no frame looked at
    had a mask), ``snapped`` (whether the masks were replaced), ``min_gain``."""
    t = len(masks)

    def one(i: int) -> tuple[np.ndarray, float | None]:
        m = np.asarray(masks[i], bool)
        frame = np.asarray(frames[i])
        s = snap_frame(frame, m)
        if m.sum() < _MIN_PIXELS:
            return s, None
        if s.sum() < _MIN_PIXELS:  # a cut that finds no animal has no evidence: the mask stands
            return m, None
        lab = cv2.cvtColor(frame, cv2.COLOR_RGB2LAB)
        ring = ring_width(m)
        gain = separation(lab, s, ring) - separation(lab, m, ring)
        return s, (gain if np.isfinite(gain) else None)

    looked = sorted(set(range(0, t, max(int(every), 1))) | ({t - 1} if t else set()))
    n = min(flow_workers(), max(t, 1))  # the share of the cores the flow takes
    with ThreadPoolExecutor(n, thread_name_prefix="colour-snap") if n > 1 else nullcontext() as pool:
        run = pool.map if pool else map
        first = dict(zip(looked, run(one, looked)))
        gains = [g for _, g in first.values() if g is not None]
        gain = float(np.median(gains)) if gains else None
        use = gain is not None and gain > min_gain
        if use:
            out = working(frames, t, np.asarray(masks[0]).shape, bool)
            rest = [i for i in range(t) if i not in first]
            for i, (s, _) in zip(rest, run(one, rest)):
                out[i] = s  # written here, in order: a scratch array is not shared between threads
            for i, (s, _) in first.items():
                out[i] = s
    report = {
        "separation_gain": None if gain is None else round(gain, 4),
        "snapped": use,
        "min_gain": min_gain,
    }
    return (out if use else masks), report
