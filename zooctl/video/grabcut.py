"""The classical automatic segmenter: a first-frame box, then GrabCut tracked along the flow.

Frame 0: inside the box, pixels that both move unlike the camera (flow residual after a RANSAC
homography) and have the box's colours (Lab histograms, box against the rest) seed GrabCut.
Frame t: the previous mask, warped along the backward flow, is the shape prior; the colour
histograms are tracked (running average of each frame's result) and the motion cue is recomputed;
together they build GrabCut's trimap in a window around the prior. Works on CPU, offline.
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

from ..errors import InputError, UsageError
from . import cues
from .flow import DISFlow, VideoFlow, compute_video_flow, warp

Box = tuple[int, int, int, int]  # x, y, w, h in pixels of the frames given to segment()


class GrabCutTracker:
    """``segment(frames, box, progress, flow) -> (T, H, W) bool``; see the module docstring.

    ``iterations``: GrabCut iterations per tracked frame (``first_iterations`` on frame 0).
    ``colour_memory``: weight of the past in the running background histogram. ``band``: width of
    the uncertain band around the propagated mask, as a fraction of the animal's size. ``demote``:
    frame-0 colour probability under which a propagated pixel that also stops moving or looking like
    the animal becomes "probably background". ``gate``: the frame-0 colour probability a pixel needs to
    be taken back into the mask (None: the 10th percentile over the first mask, times ``gate_scale``,
    at most ``max_gate``). ``work_size``: longest side GrabCut works at (larger frames are
    segmented downscaled and the masks upsampled; None: full size). ``box_margin``: the band around
    the first-frame box that may still hold the animal, as a fraction of the box's longer side.
    """

    name = "grabcut"
    uses_flow = True  # the store passes the flow it computed anyway, instead of computing it twice

    def __init__(
        self,
        iterations: int = 2,
        first_iterations: int = 4,
        colour_memory: float = 0.7,
        band: float = 0.08,
        demote: float = 0.35,
        gate: float | None = None,
        gate_scale: float = 1.0,
        max_gate: float = 0.5,
        flow_preset: str = "medium",
        work_size: int | None = 427,
        box_margin: float = 0.0,
    ) -> None:
        if iterations < 1 or first_iterations < 1:
            raise UsageError("GrabCut needs at least one iteration")
        if not 0.0 <= colour_memory < 1.0:
            raise UsageError(f"colour_memory must be in [0, 1), got {colour_memory}")
        self.iterations = iterations
        self.first_iterations = first_iterations
        self.colour_memory = colour_memory
        self.flow_preset = flow_preset
        self.band = band
        self.demote = demote
        self.gate = gate
        self.gate_scale = gate_scale
        self.max_gate = max_gate
        self.work_size = work_size
        self.box_margin = box_margin

    def segment(
        self,
        frames: np.ndarray,
        box: Box | None = None,
        progress: Callable[[int, int], None] | None = None,
        flow: VideoFlow | None = None,
    ) -> np.ndarray:
        """(T, H, W, 3) uint8 RGB frames, first-frame box -> (T, H, W) bool masks."""
        t, h, w = frames.shape[:3]
        if t < 2:
            raise InputError("the grabcut segmenter needs at least 2 frames (it uses motion)")
        if box is not None:
            box = _check_box(box, w, h)
        cv2.setRNGSeed(
            0
        )  # GrabCut seeds its colour models with k-means on OpenCV's global RNG: be repeatable
        if flow is None:
            flow = compute_video_flow(DISFlow(self.flow_preset), frames)
        scale = self.work_size / max(h, w) if self.work_size and max(h, w) > self.work_size else 1.0
        if scale == 1.0:
            return self._segment(frames, box, progress, flow)
        # GrabCut and its cues work at a bounded size (4x faster at 480p, and the band/window sizes
        # were tuned there); the masks come back up with a linear upsample of their 0/1 values
        sw, sh = round(w * scale), round(h * scale)
        small = np.stack([cv2.resize(f, (sw, sh), interpolation=cv2.INTER_AREA) for f in frames])
        small_flow = VideoFlow(*(_resize_flow(f, sw, sh) for f in (flow.forward, flow.backward)), None, None)
        small_box = None if box is None else tuple(int(round(v * scale)) for v in box)
        masks = self._segment(small, small_box, progress, small_flow)
        return np.stack(
            [cv2.resize(m.astype(np.float32), (w, h), interpolation=cv2.INTER_LINEAR) > 0.5 for m in masks]
        )

    def _segment(self, frames, box, progress, flow) -> np.ndarray:
        t, h, w = frames.shape[:3]
        residual0 = cues.background_motion_residual(flow.forward[0])
        box = _check_box(box, w, h) if box is not None else _box_from_motion(residual0)
        bins = [cues.lab_bins(f) for f in frames]
        masks = np.zeros((t, h, w), bool)
        masks[0] = self._first(frames[0], bins[0], residual0, box)
        hist_fg = cues.colour_histogram(bins[0], masks[0])
        hist_bg = cues.colour_histogram(bins[0], ~masks[0])
        gate = self.gate
        if (
            gate is None and masks[0].any()
        ):  # adaptive: how animal-like its least typical tenth of colours looks
            p0 = cues.colour_probability(bins[0], hist_fg, hist_bg)[masks[0]]
            gate = min(self.gate_scale * float(np.percentile(p0, 10)), self.max_gate)
        gate = 0.0 if gate is None else gate
        if progress:
            progress(1, t)
        for i in range(1, t):
            prior = warp(masks[i - 1].astype(np.float32), flow.backward[i - 1]) > 0.5
            motion_flow = flow.forward[i] if i < t - 1 else -flow.backward[i - 1]
            masks[i] = self._track(frames[i], bins[i], prior, motion_flow, hist_fg, hist_bg, gate)
            if masks[i].any() and (~masks[i]).any():
                # the animal's colours stay those of frame 0 (a slow leak must not teach it the water);
                # the background's follow the camera
                a = self.colour_memory
                hist_bg = a * hist_bg + (1 - a) * cues.colour_histogram(bins[i], ~masks[i])
            if progress:
                progress(i + 1, t)
        return masks

    # -- steps ------------------------------------------------------------------------------------

    def _first(self, frame: np.ndarray, bins: np.ndarray, residual: np.ndarray, box: Box) -> np.ndarray:
        h, w = bins.shape
        inbox = cues.box_mask((h, w), box)
        p_colour = cues.colour_probability(
            bins, cues.colour_histogram(bins, inbox), cues.colour_histogram(bins, ~inbox)
        )
        p_motion = cues.motion_probability(residual, inbox)
        seed = cues.largest_components((np.sqrt(p_colour * p_motion) > 0.5) & inbox)
        if seed.sum() < 0.1 * inbox.sum():  # the animal barely moves yet: trust colour alone
            seed = cues.largest_components((p_colour > 0.5) & inbox)
        if seed.sum() < 0.05 * inbox.sum():  # nothing stands out: GrabCut's own rectangle start
            seed = inbox
        # a hand-drawn box often cuts off a paw or an ear: a margin around it is only "probably"
        # background, so the animal's colours do not end up in GrabCut's background model
        x, y, bw, bh = box
        m = round(self.box_margin * max(bw, bh))
        trimap = np.full((h, w), cv2.GC_BGD, np.uint8)
        trimap[cues.box_mask((h, w), (x - m, y - m, bw + 2 * m, bh + 2 * m))] = cv2.GC_PR_BGD
        trimap[seed] = cv2.GC_PR_FGD
        return _clean(_grabcut(frame, trimap, self.first_iterations), seed)

    def _track(self, frame, bins, prior, motion_flow, hist_fg, hist_bg, gate: float) -> np.ndarray:
        h, w = bins.shape
        box = cues.box_of(prior)
        if box is None:  # lost: nothing to propagate (the animal left the frame)
            return prior
        x, y, bw, bh = box
        size = float(np.sqrt(prior.sum()))
        pad = int(0.15 * max(bw, bh)) + 4
        window = cues.box_mask((h, w), (x - pad, y - pad, bw + 2 * pad, bh + 2 * pad))
        # colour: frame 0's model (the animal's colours stay those it showed first; a slow leak must not
        # teach it the water) averaged with this frame's own (the propagated mask against the rest)
        p_first = cues.colour_probability(bins, hist_fg, hist_bg)
        p_local = cues.colour_probability(
            bins, cues.colour_histogram(bins, prior), cues.colour_histogram(bins, ~window)
        )
        p_colour = 0.5 * (p_first + p_local)
        p_motion = cues.motion_probability(cues.background_motion_residual(motion_flow), window)
        cue = np.sqrt(p_colour * p_motion)
        # a limb the flow lost is taken back when it moves unlike the camera and looks like the animal
        grow = prior | (window & (cue > 0.5) & (p_first > gate))
        around = cv2.dilate(grow.astype(np.uint8), cues.disk(self.band * size)).astype(bool) & window
        sure = (
            cv2.erode(prior.astype(np.uint8), cues.disk(0.12 * size)).astype(bool)
            & (cue > 0.5)
            & (p_colour > 0.3)
        )
        trimap = np.full((h, w), cv2.GC_BGD, np.uint8)
        trimap[around] = cv2.GC_PR_BGD
        trimap[grow] = cv2.GC_PR_FGD
        # drift: propagated pixels that neither look like frame 0's animal nor move/look like this frame's
        trimap[prior & (p_first < self.demote) & ((p_motion < 0.5) | (p_local < 0.5))] = cv2.GC_PR_BGD
        trimap[sure] = cv2.GC_FGD
        return _clean(_grabcut(frame, trimap, self.iterations), prior)


def _grabcut(frame: np.ndarray, trimap: np.ndarray, iterations: int) -> np.ndarray:
    """GrabCut on the window around the non-definite-background part of ``trimap``; (H, W) bool."""
    h, w = trimap.shape
    box = cues.box_of(trimap != cv2.GC_BGD)
    if box is None:
        return np.zeros((h, w), bool)
    x, y, bw, bh = box
    m = max(bw, bh) // 2 + 8  # enough definite background around for a fair background model
    x0, y0, x1, y1 = max(x - m, 0), max(y - m, 0), min(x + bw + m, w), min(y + bh + m, h)
    sub = np.ascontiguousarray(trimap[y0:y1, x0:x1])
    fg_labels = (cv2.GC_FGD, cv2.GC_PR_FGD)
    if not np.isin(sub, fg_labels).any() or np.isin(sub, fg_labels).all():
        return np.isin(trimap, fg_labels)
    img = np.ascontiguousarray(frame[y0:y1, x0:x1, ::-1])  # OpenCV's GrabCut is BGR
    bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    try:
        cv2.grabCut(img, sub, None, bgd, fgd, iterations, cv2.GC_INIT_WITH_MASK)
    except cv2.error:  # a GMM with too few samples of one class: keep the trimap's own guess
        pass
    out = np.zeros((h, w), bool)
    out[y0:y1, x0:x1] = np.isin(sub, fg_labels)
    return out


def _clean(mask: np.ndarray, reference: np.ndarray) -> np.ndarray:
    return cues.fill_holes(cues.largest_components(mask, reference=reference))


def _check_box(box: Box, w: int, h: int) -> Box:
    x, y, bw, bh = (int(round(v)) for v in box)
    x0, y0, x1, y1 = max(x, 0), max(y, 0), min(x + bw, w), min(y + bh, h)
    if bw <= 0 or bh <= 0 or x1 - x0 < 4 or y1 - y0 < 4:
        raise UsageError(
            f"--box {x},{y},{bw},{bh} does not cover a part of the {w}x{h} first frame",
            hint="give x,y,w,h in pixels of the original video, around the animal in its first frame",
        )
    return x0, y0, x1 - x0, y1 - y0


def _box_from_motion(residual: np.ndarray) -> Box:
    """The box of the largest region that moves unlike the camera in the first frame pair."""
    h, w = residual.shape
    moving = cues.motion_probability(residual, np.ones((h, w), bool), min_threshold=1.0) > 0.5
    moving = cv2.morphologyEx(moving.astype(np.uint8), cv2.MORPH_OPEN, cues.disk(2)).astype(bool)
    moving = cues.largest_components(moving, keep_ratio=1.0)
    box = cues.box_of(moving)
    if box is None or moving.sum() < 0.002 * h * w or moving.sum() > 0.8 * h * w:
        raise UsageError(
            "no single moving animal found in the first frames to start segmentation from",
            hint="give --box x,y,w,h around the animal in the first frame",
        )
    return box


def _resize_flow(flow: np.ndarray, w: int, h: int) -> np.ndarray:
    """(N, H, W, 2) flow -> (N, h, w, 2), displacements rescaled to the new pixel size."""
    sx, sy = w / flow.shape[2], h / flow.shape[1]
    out = np.stack([cv2.resize(f, (w, h), interpolation=cv2.INTER_AREA) for f in flow])
    out[..., 0] *= sx
    out[..., 1] *= sy
    return out
