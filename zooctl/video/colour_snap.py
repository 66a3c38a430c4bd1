"""The masks snapped to the animal's colours: a last GrabCut per frame, kept for a video only where
it makes the animal's colours stand apart from its surroundings.

A tracker's and a learned relabelling's masks can take in a blob of background beside the animal
(grass up to the horizon beside a grey dolphin, the ground a fox has just crossed): the motion and
the coarse network features call it animal, the colours do not. `snap_frame` runs GrabCut seeded by
the mask itself (inside: probably the animal; a ring around it: probably background; beyond: sure
background), so each pixel goes to the colour model it fits. On real footage the ground is often
the animal's colour and the snap then takes in ground or drops blurred legs, so a video is snapped
only when the snap separates the mask's colours from its ring's more than the masks did: the median
over eight frames spread over the video of `separation` after minus before exceeds ``min_gain``
(`snap_video`), so a video left alone costs eight cuts whatever its length. The threshold was
chosen on the seven shared DAVIS videos and two 28-video `zooctl bench make` sets, the
leave-one-video-out figures beside it (`bench/colour_snap.py`; BENCHMARKS.md, "Masks snapped to
the animal's colours").
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from contextlib import nullcontext

import cv2
import numpy as np

from . import cues
from .flow import flow_workers
from .grabcut import _grabcut
from .scratch import working

BAND = 0.15  # the ring of probable background, a fraction of the mask's square-root area
ITERATIONS = 3
# the median separation gain over a video's frames above which its masks are snapped
MIN_GAIN = 0.005
LOOKS = 8  # frames the gate looks at, spread over the video from its first to its last
_MIN_PIXELS = 16
BINS = 8  # Lab levels a channel of the separation's histograms


def ring_width(mask: np.ndarray, band: float = BAND) -> int:
    """The ring's width in pixels for an (H, W) bool mask: ``band`` times the square root of its area."""
    return max(int(round(band * np.sqrt(max(int(mask.sum()), 1)))), 2)


def snap_frame(
    frame: np.ndarray, mask: np.ndarray, band: float = BAND, iterations: int = ITERATIONS
) -> np.ndarray:
    """(H, W, 3) uint8 RGB frame and (H, W) bool mask -> (H, W) bool mask after GrabCut seeded by it.

    Inside the mask: probably the animal; a ring ``band`` x sqrt(area) wide around it: probably
    background; beyond: background. The tracker's cut (`grabcut._grabcut`) runs on the mask's box
    grown by three rings. A mask under 16 pixels comes back unchanged."""
    m = np.asarray(mask, bool)
    if m.sum() < _MIN_PIXELS:
        return m
    r = ring_width(m, band)
    trimap = np.full(m.shape, cv2.GC_BGD, np.uint8)
    trimap[cv2.dilate(m.astype(np.uint8), cues.disk(r)) > 0] = cv2.GC_PR_BGD
    trimap[m] = cv2.GC_PR_FGD
    return _grabcut(frame, trimap, iterations, margin=2 * r)  # the ring's box grown by two more


def separation(bins: np.ndarray, mask: np.ndarray, ring: int) -> float:
    """1 - the Bhattacharyya coefficient of the colours inside ``mask`` and in the ring ``ring``
    pixels wide outside it, for a frame's (H, W) Lab colour bins (`cues.lab_bins` at ``BINS``):
    0 the same colours, 1 none shared. NaN for a mask or ring under 16 pixels."""
    m = np.asarray(mask, bool)
    around = (cv2.dilate(m.astype(np.uint8), cues.disk(ring)) > 0) & ~m
    if m.sum() < _MIN_PIXELS or around.sum() < _MIN_PIXELS:
        return float("nan")
    p, q = (np.bincount(bins[x], minlength=BINS**3) / x.sum() for x in (m, around))
    return 1.0 - float(np.sum(np.sqrt(p * q)))


def looked_at_frames(t: int, looks: int = LOOKS) -> list[int]:
    """The indices of the ``looks`` frames, evenly spread from the first to the last, that the
    gate reads in a video of ``t`` frames (all of them when ``t <= looks``)."""
    if t <= 0:
        return []
    return sorted({int(i) for i in np.round(np.linspace(0, t - 1, min(max(int(looks), 1), t)))})


def snap_video(frames, masks, min_gain: float = MIN_GAIN, looks: int = LOOKS) -> tuple[object, dict]:
    """(T, h, w, 3) uint8 RGB frames and (T, h, w) bool masks -> (masks, report).

    ``looks`` frames spread over the video (`looked_at_frames`) are snapped first (`snap_frame`,
    frames side by side on `flow.flow_workers` threads) and each one's separation gain measured:
    `separation` of the snapped mask minus that of the given one, each with the given mask's ring
    width (a frame the cut leaves empty keeps its mask and has no gain). When the median gain
    exceeds ``min_gain`` the other frames are snapped too and the snapped masks replace the given
    ones, all of them, in memory or, for frames that wait in scratch files (a long video), in a
    scratch array; else the given masks come back (a video left as it was costs ``looks`` cuts,
    however long). ``report``: ``separation_gain`` (the median, None when no frame looked at had a
    mask), ``snapped`` (whether the masks were replaced), ``min_gain``."""
    t = len(masks)

    def cut(frame: np.ndarray, m: np.ndarray) -> np.ndarray:
        s = snap_frame(frame, m)  # ``m`` itself when under 16 pixels
        return m if s.sum() < _MIN_PIXELS else s  # no animal found: no evidence

    def looked_at(i: int) -> tuple[np.ndarray, float | None]:
        m, frame = np.asarray(masks[i], bool), np.asarray(frames[i])
        s = cut(frame, m)
        if s is m:  # too small a mask, or a cut that found nothing
            return s, None
        bins, ring = cues.lab_bins(frame, BINS), ring_width(m)
        gain = separation(bins, s, ring) - separation(bins, m, ring)
        return s, (gain if np.isfinite(gain) else None)

    def rest_of(i: int) -> np.ndarray:
        return cut(np.asarray(frames[i]), np.asarray(masks[i], bool))

    looked = looked_at_frames(t, looks)
    n = min(flow_workers(), max(t, 1))  # the share of the cores the flow takes
    with ThreadPoolExecutor(n, thread_name_prefix="colour-snap") if n > 1 else nullcontext() as pool:
        run = pool.map if pool else map
        first = dict(zip(looked, run(looked_at, looked)))
        gains = [g for _, g in first.values() if g is not None]
        gain = float(np.median(gains)) if gains else None
        use = gain is not None and gain > min_gain
        if use:
            out = working(frames, t, np.asarray(masks[0]).shape, bool)
            rest = [i for i in range(t) if i not in first]
            for i, s in zip(rest, run(rest_of, rest)):
                out[i] = s  # written here, in order: a scratch array is not shared between threads
            for i, (s, _) in first.items():
                out[i] = s
    report = {
        "separation_gain": None if gain is None else round(gain, 4),
        "snapped": use,
        "min_gain": min_gain,
    }
    return (out if use else masks), report
