"""The classical automatic segmenter: a seed mask on one frame, then GrabCut tracked along the flow.

Seed: the localiser (`zooctl.video.localise`: ImageNet animal class maps fused with motion) looks
at keyframes, picks the one where it sees an animal most surely and seeds GrabCut around the main
animal there (the class map's region starts as probably the animal), also from the part of the
seed the class map is surest of (what moves with the animal, its reflection or wake, has its
colours but less class evidence); that tighter mask wins where the class map says that what it
leaves out is not the animal. A box (on any frame, ``box_frame``) chooses which animal: the
localiser's region inside it is carried along the flow (`zooctl.video.hint`) and only evidence
connected to it counts, on every frame; the seeding is then the same as without a box. Where the
localiser sees no animal in the box, or the result on the box's frame is not what the box was drawn
around, the box's own pixels that move unlike the camera (flow residual after a RANSAC homography)
and have the box's colours (Lab histograms, box against the rest) seed GrabCut on the box's frame.
Tracking, forwards and backwards from the seed frame: the neighbouring mask, warped along the flow,
is the shape prior; the colour histograms are tracked and the motion cue is recomputed; together
they build GrabCut's trimap in a window around the prior. On keyframes, and when the mask shrinks
or vanishes, the localiser checks it: a mask that misses the animal it sees is replaced by a fresh
seed (re-seeding). Works on CPU, offline.
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from functools import partial

import cv2
import numpy as np

from ..errors import InputError, UsageError
from . import cues, hint
from .flow import DISFlow, VideoFlow, compute_video_flow, fb_inconsistent, resize_flow, warp
from .localise import Evidence, Localiser, class_name, fuse, main_region
from .mask_quality import frame_j
from .scratch import Resized, ScratchArray, working

# A pass from another seed frame whose mask on a frame overlaps the first pass's this much has found
# the same animal: the rest of that direction would repeat the first pass, which it takes instead.
JOIN_IOU = 0.95

Box = tuple[int, int, int, int]  # x, y, w, h in pixels of the frames given to segment()


class GrabCutTracker:
    """``segment(frames, box, progress, flow, box_frame) -> (T, H, W) bool``; see the module docstring.
    After a run, ``report`` says how each frame got its mask ("box", "localiser", "tracked",
    "re-seeded", "empty") and the animal classes the localiser saw.

    ``iterations``: GrabCut iterations per tracked frame (``first_iterations`` on the seed frame).
    ``colour_memory``: weight of the past in the running background histogram. ``band``: width of
    the uncertain band around the propagated mask, as a fraction of the animal's size. ``demote``:
    frame-0 colour probability under which a propagated pixel that also stops moving or looking like
    the animal becomes "probably background". ``gate``: the frame-0 colour probability a pixel needs to
    be taken back into the mask (None: the 10th percentile over the first mask, times ``gate_scale``,
    at most ``max_gate``). ``work_size``: longest side GrabCut works at (larger frames are
    segmented downscaled and the masks upsampled; None: full size). ``box_margin``: the band around
    the first-frame box that may still hold the animal, as a fraction of the box's longer side.
    ``localise``: check tracked masks against the localiser and re-seed. ``key_every``: keyframe
    spacing. ``min_confidence``: the animal-class probability the surest cell of the class map needs
    for the map to be trusted (`zooctl.video.localise.Evidence`; else motion alone seeds). ``min_agreement``: the share of the localiser's animal
    region a tracked mask must touch to be kept. ``seed_margin``: how far past the class map's region
    the animal may reach, as a fraction of its longer side. ``localiser_width``: network input width.
    ``keep_moving``: while tracking, pixels next to the mask that surely move unlike the camera
    (reliable flow) and have the animal's colours (``keep_colour``) are kept as sure foreground.
    ``reseed_colour``: the mean seed-frame colour probability a fresh seed needs to replace a
    tracked mask. ``reliable_motion``: flow that fails the forward-backward check (ripples, glints) is no motion
    evidence, in the seed, the localiser and tracking. ``core_quantile``: a localiser seed is also cut
    from its core, its pixels at or over this quantile of the class map (0.5: the more animal-like
    half) in the colours typical of them (0: never; see `_seed_in_box`). ``hold_still``: the
    propagated mask's interior (eroded by an eighth of its size) that keeps the seed frame's animal
    colours stays sure foreground when it does not move (else only where it moves too).
    ``seed_from_map``: a localiser seed starts GrabCut with the class map's region (over half its
    peak, inside the seed's box) as probably the animal, not only the box's moving, box-coloured
    pixels (the animal's parts in the ground's colours). ``warm_models``: a tracked frame's GrabCut
    starts from the colour models the previous frame's cut ended with (then learns this frame's)
    instead of a fresh k-means: the same colours a frame later, in less time. ``flip``: the
    localiser looks at each frame and its mirror image (`zooctl.video.localise.Localiser`).
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
        localise: bool = True,
        key_every: int = 10,
        min_confidence: float = 0.85,
        min_agreement: float = 0.3,
        seed_margin: float = 0.1,
        localiser_width: int = 448,
        keep_moving: bool = False,
        keep_colour: float = 0.5,
        reliable_motion: bool = False,
        reseed_colour: float = 0.5,
        core_quantile: float = 0.5,
        hold_still: bool = True,
        seed_from_map: bool = True,
        warm_models: bool = True,
        flip: bool = False,
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
        if key_every < 1:
            raise UsageError(f"key_every must be at least 1, got {key_every}")
        self.localise = localise
        # a segmenter that tries other seed frames sets the one to start from (no box) here: the
        # frames are then those of the last call, whose looks, colour bins and masks it asked to keep
        self.start_at: int | None = None
        self.keep_looks = False
        self._kept: tuple | None = None
        self._join: tuple | None = None  # (masks, how) of the first pass, while another seed's runs
        self.key_every = key_every
        self.min_confidence = min_confidence
        self.min_agreement = min_agreement
        self.seed_margin = seed_margin
        self.localiser_width = localiser_width
        self.keep_moving = keep_moving
        self.keep_colour = keep_colour
        self.reliable_motion = reliable_motion
        self.reseed_colour = reseed_colour
        if not 0.0 <= core_quantile < 1.0:
            raise UsageError(f"core_quantile must be in [0, 1), got {core_quantile}")
        self.core_quantile = core_quantile
        self.hold_still = hold_still
        self.seed_from_map = seed_from_map
        self.warm_models = warm_models
        self.flip = flip
        self._loc: Localiser | None = None
        self.report: dict = {}

    def segment(
        self,
        frames: np.ndarray,
        box: Box | None = None,
        progress: Callable[[int, int], None] | None = None,
        flow: VideoFlow | None = None,
        box_frame: int = 0,
        working_frames=None,
    ) -> np.ndarray:
        """(T, H, W, 3) uint8 RGB frames, optional box on frame ``box_frame`` -> (T, H, W) bool masks.
        ``working_frames``: the frames at `flow_size` (INTER_AREA), when the caller has them."""
        t, h, w = frames.shape[:3]
        if t < 2:
            raise InputError("the grabcut segmenter needs at least 2 frames (it uses motion)")
        if not 0 <= box_frame < t:
            raise UsageError(
                f"--box-frame {box_frame} is not a frame of this {t}-frame video",
                hint=f"give a stored frame number from 0 to {t - 1}",
            )
        if box is not None:
            box = _check_box(box, w, h, box_frame)
        if flow is None:
            flow = compute_video_flow(DISFlow(self.flow_preset), np.asarray(frames))
        sw, sh = self.flow_size(w, h)
        if (sw, sh) == (w, h):
            return self._honour(frames, box, box_frame, progress, flow)
        # GrabCut and its cues work at a bounded size (much faster, BENCHMARKS.md, "Measurements behind
        # code choices"; the band/window sizes were tuned there); the masks come back up with a
        # linear upsample of their 0/1 values.
        # A lazy video (frames read from the store's file) keeps its working set in scratch files.
        scale = self._scale(w, h)
        small = working_frames
        if small is None:
            small = working(frames, t, (sh, sw, 3), np.uint8)
            for i in range(t):
                small[i] = cv2.resize(frames[i], (sw, sh), interpolation=cv2.INTER_AREA)
        if tuple(flow.forward.shape[1:3]) == (sh, sw):  # given at the size GrabCut works at
            small_flow = flow  # the same object: the motion residuals it makes are shared
        else:
            small_flow = VideoFlow(
                *(resize_flows(f, sw, sh, frames) for f in (flow.forward, flow.backward)), None, None
            )
        small_box = None if box is None else tuple(int(round(v * scale)) for v in box)
        masks = self._honour(small, small_box, box_frame, progress, small_flow)
        if isinstance(frames, np.ndarray):
            return np.stack(
                [
                    cv2.resize(m.astype(np.float32), (w, h), interpolation=cv2.INTER_LINEAR) > 0.5
                    for m in masks
                ]
            )
        return Resized(masks, w, h)

    def forget(self) -> None:
        """Drop what the last call kept (``keep_looks``) for calls with ``start_at``."""
        self._kept = None

    def flow_size(self, w: int, h: int) -> tuple[int, int]:
        """(w, h) GrabCut works at for frames of (w, h): the flow it reads, at that size."""
        scale = self._scale(w, h)
        return (w, h) if scale == 1.0 else (round(w * scale), round(h * scale))

    def _scale(self, w: int, h: int) -> float:
        return self.work_size / max(h, w) if self.work_size and max(h, w) > self.work_size else 1.0

    def _honour(self, frames, box, box_frame, progress, flow) -> np.ndarray:
        """`_segment`, and with a box whose animal the localiser chose: again from the box's own seed
        when the mask on the box's frame is not what the box was drawn around. The frames' colour
        bins and the localiser's looks (they depend on the frames alone) serve both passes.
        The keyframes' looks are taken on a second thread from the last one back, while the first
        pass takes them from the first one on."""
        t = len(frames)
        kept = self._kept
        if self.start_at is not None and kept is not None and kept[0] == frames.shape:
            self._evidence, bins = kept[1], kept[2]  # the same frames again, from another seed
            self._join = kept[3:]
            try:
                return self._segment(frames, bins, None, box_frame, progress, flow)
            finally:
                self._join = None
        self._evidence = _Seen(frames)
        ahead = None
        if self.localise:
            self._localiser()
            keys = sorted(set(range(0, t, self.key_every)) | {t - 1}, reverse=True)
            self._stop_ahead = False
            ahead = threading.Thread(target=self._look_ahead, args=(frames, keys), name="localiser-ahead")
            ahead.start()
        try:
            bins = _Bins(frames)
            masks = self._segment(frames, bins, box, box_frame, progress, flow)
            if self.keep_looks:
                self._kept = (frames.shape, self._evidence, bins, masks, list(self.report["seeding"]))
            if box is None or self.report["box_use"] == "seeded" or hint.agrees(masks[box_frame], box):
                return masks
            return self._segment(frames, bins, box, box_frame, progress, flow, box_seed=True)
        finally:
            self._stop_ahead = True
            if ahead is not None:
                ahead.join()

    def _look_ahead(self, frames, keys) -> None:
        """The localiser's looks at ``keys`` into its cache (a frame the tracker is looking at
        already is left to it; an error is left to the tracker to meet)."""
        for k in keys:
            if self._stop_ahead:
                return
            try:
                self._seen(frames, k)
            except Exception:
                return

    def _segment(self, frames, bins, box, box_frame, progress, flow, box_seed: bool = False) -> np.ndarray:
        t, h, w = frames.shape[:3]
        self._animals_seen = 0
        self._seed_ranking: list[int] = []
        self._within: np.ndarray | None = None  # (T, H, W) bool: where the box's animal is
        how = ["tracked"] * t
        if box is not None:
            s, masks_s, how[s] = self._start_from_box(frames, bins, flow, box, box_frame, box_seed)
        else:
            s, masks_s = self._start(frames, bins, flow)
            how[s] = "localiser"
        masks = working(frames, t, (h, w), bool)
        masks[s] = masks_s
        if not masks_s.any():
            how[s] = "empty"
        hist_fg = cues.colour_histogram(bins[s], masks[s])
        hist_bg0 = cues.colour_histogram(bins[s], ~masks[s])
        gate = self.gate
        if (
            gate is None and masks[s].any()
        ):  # adaptive: how animal-like its least typical tenth of colours looks
            p0 = cues.colour_probability(bins[s], hist_fg, hist_bg0)[masks[s]]
            gate = min(self.gate_scale * float(np.percentile(p0, 10)), self.max_gate)
        gate = 0.0 if gate is None else gate
        # from the seed frame forwards to the end, and backwards to the start: each direction starts
        # from the seed frame's mask and colours, so the two run side by side (GrabCut and the cues
        # release the GIL), the backward one on a thread of its own
        forward, backward = range(s + 1, t), range(s - 1, -1, -1)
        track = partial(self._track_along, frames, bins, flow, masks, how, s, hist_fg, hist_bg0, gate)
        done, cv = [1], threading.Condition()
        self._localising = threading.Lock()  # the localiser's cache and counts, one direction at a time

        def step() -> None:
            with cv:
                done[0] += 1
                cv.notify_all()

        def report() -> None:
            if progress:
                with cv:
                    n = done[0]
                progress(n, t)

        report()
        if not forward or not backward:  # one direction (the seed is the first or the last frame)
            track(forward or backward, lambda: (step(), report()))
        else:
            failed: list[BaseException] = []
            stop = threading.Event()  # the forward direction failed: the backward one ends too

            def step_back() -> None:
                step()
                if stop.is_set():
                    raise _Stopped

            def behind() -> None:
                try:
                    track(backward, step_back)
                except _Stopped:
                    pass
                except BaseException as exc:
                    failed.append(exc)
                finally:
                    with cv:
                        cv.notify_all()

            worker = threading.Thread(target=behind, name="grabcut-backward", daemon=True)
            worker.start()
            try:
                track(forward, lambda: (step(), report()))
                while worker.is_alive():
                    with cv:
                        cv.wait(0.5)
                    report()
            finally:
                stop.set()
                worker.join()
            if failed:
                raise failed[0]
            report()
        self.report = self._report(how, s)
        if box is not None:
            self.report["box_frame"] = box_frame
            self.report["box_use"] = "seeded" if how[s] == "box" else "chose the animal"
        return masks

    def _track_along(self, frames, bins, flow, masks, how, s, hist_fg, hist_bg0, gate, order, step) -> None:
        """Track from the seed frame ``s`` over ``order`` (consecutive frames, away from ``s``),
        writing ``masks[i]`` and ``how[i]``; ``step()`` after each frame. The next frame's motion
        residual (it needs the flow alone) is made on a helper thread while this one is tracked."""
        t, h, w = frames.shape[:3]
        hist_bg = hist_bg0
        order = list(order)
        models: list = []
        with ThreadPoolExecutor(1, thread_name_prefix="grabcut-motion") as ahead:
            coming = ahead.submit(self._coming, flow, bins, order[0]) if order else None
            for j, i in enumerate(order):
                residual = coming.result()  # type: ignore[union-attr]
                if j + 1 < len(order):
                    coming = ahead.submit(self._coming, flow, bins, order[j + 1])
                src = i - 1 if i > s else i + 1
                pull = flow.backward[i - 1] if i > s else flow.forward[i]  # takes frame src onto i's grid
                prior = warp(masks[src].astype(np.float32), pull) > 0.5
                m = np.zeros((h, w), bool)
                if prior.any():
                    m = self._track(
                        frames[i],
                        bins[i],
                        prior,
                        residual,
                        hist_fg,
                        hist_bg,
                        gate,
                        self._unreliable(flow, i) if self.reliable_motion else None,
                        models if self.warm_models else None,
                    )
                if self.localise and self._due(i, t, m, prior):
                    with self._localising:
                        new = self._reseed(frames, bins, flow, i, m, hist_fg, hist_bg)
                    if new is not None:
                        m, how[i] = new, "re-seeded"
                masks[i] = m
                if self._join is not None and frame_j(m, self._join[0][i]) >= JOIN_IOU:
                    # the first seed's animal again: from here on its pass (`JOIN_IOU`)
                    for k in order[j:]:
                        masks[k], how[k] = self._join[0][k], self._join[1][k]
                        step()
                    return
                if not m.any():
                    how[i] = "empty"
                elif (~m).any():
                    # the animal's colours stay those of the seed frame (a slow leak must not teach it
                    # the water); the background's follow the camera
                    a = self.colour_memory
                    hist_bg = a * hist_bg + (1 - a) * cues.colour_histogram(bins[i], ~m)
                step()

    # -- the localiser: where to start and when to start again -------------------------------------

    def _residual(self, flow, i: int) -> np.ndarray:
        """Frame i's motion unlike the camera, in pixels (with ``reliable_motion``: 0 where the flow
        fails the forward-backward check)."""
        r = flow.residual(i)
        if not self.reliable_motion:
            return r
        return np.where(_closed(self._unreliable(flow, i)), 0.0, r).astype(np.float32)

    def _coming(self, flow, bins, i: int) -> np.ndarray:
        """Frame i's motion residual, and its colour bins made (both need the frame and flow alone)."""
        bins[i]
        return flow.residual(i)

    @staticmethod
    def _unreliable(flow, i: int) -> np.ndarray:
        """(H, W) bool: frame i's pixels whose flow fails the forward-backward check (ripples,
        glints, smoke: texture that changes rather than moves)."""
        if i < len(flow.forward):
            return fb_inconsistent(flow.forward[i], flow.backward[i])
        return fb_inconsistent(flow.backward[i - 1], flow.forward[i - 1])

    def _localiser(self) -> Localiser:
        if self._loc is None:
            self._loc = Localiser(width=self.localiser_width, flip=self.flip)
        return self._loc

    def _seen(self, frames, i: int) -> Evidence:
        return self._evidence.get(i, lambda: self._localiser().evidence(frames[i]))

    def _fused(self, frames, flow, i: int) -> tuple[np.ndarray, Evidence]:
        ev = self._seen(frames, i)
        h, w = ev.animal.shape
        motion = cues.motion_probability(self._residual(flow, i), np.ones((h, w), bool), min_threshold=1.0)
        if motion.mean() > 0.5:  # most of the frame "moves": the camera model failed, not an animal
            motion = None
        score = fuse(ev, motion)
        if ev.confidence < self.min_confidence:  # no part of the frame surely an animal: motion alone
            score = np.zeros_like(score) if motion is None else motion
        if self._within is not None:  # a box chose the animal: only the evidence connected to it counts
            score = hint.focus(score, self._within[i])
        return score, ev

    def _start(self, frames, bins, flow, extra: int | None = None) -> tuple[int, np.ndarray]:
        """The frame to start from (the most confidently seen animal among keyframes, and frame
        ``extra``) and its mask."""
        t = len(frames)
        keys = sorted(set(range(0, t, self.key_every)) | {t - 1} | ({extra} - {None}))
        scores = {}
        for k in keys:
            ev = self._seen(frames, k)
            region, _ = main_region(self._fused(frames, flow, k)[0])
            scores[k] = ev.confidence * float(region.any()) + 1e-3 * float(region.mean())
        # the keyframes that see an animal, best first (the first key of a tie, as before)
        self._seed_ranking = sorted((k for k in keys if scores[k] > 0), key=lambda k: -scores[k])
        best = max(keys, key=lambda k: (scores[k], -k))
        if self.start_at is not None and extra is None:
            best = self.start_at
        return best, self._seed(frames, bins, flow, best)

    def _start_from_box(self, frames, bins, flow, box: Box, b: int, box_seed: bool):
        """(seed frame, its mask, how it was seeded) given a box on frame b.

        The box chooses the animal: the localiser's main region inside it, carried along the flow
        to every frame, is the only place the localiser may seed (and re-seed) from; the seed frame
        and the seed are then found as without a box. Where the localiser sees no animal in the box
        (a class map it does not trust, or ``box_seed``), the box's own pixels seed frame b.
        """
        if self.localise and not box_seed:
            score, ev = self._fused(frames, flow, b)
            region, _ = main_region(hint.focus(score, cues.box_mask(score.shape, box)))
            region &= cues.box_mask(score.shape, box)
            if ev.confidence >= self.min_confidence and region.any():
                within = working(frames, len(frames), score.shape, bool)
                self._within = hint.carry(region, flow.forward, flow.backward, b, out=within)
                s, seed = self._start(frames, bins, flow, extra=b)
                if seed.any():
                    return s, seed, "localiser"
                self._within = None
        return b, self._first(frames[b], bins[b], self._residual(flow, b), box), "box"

    def _seed(self, frames, bins, flow, i: int) -> np.ndarray:
        """A mask of the main animal in frame i from the localiser alone (empty when none is seen)."""
        score, _ = self._fused(frames, flow, i)
        region, count = main_region(score)
        self._animals_seen = max(self._animals_seen, count)
        h, w = score.shape
        if not region.any():
            return np.zeros((h, w), bool)
        # seed as from a user's box around the evidence: the whole connected part of the weaker
        # evidence (the class map is blurry, motion stops at still limbs), and a little past it
        n, lab = cv2.connectedComponents((score > 0.4).astype(np.uint8), connectivity=8)
        hit = np.unique(lab[region])
        x, y, bw, bh = cues.box_of(np.isin(lab, hit[hit > 0]) | region)
        m = round(self.seed_margin * max(bw, bh))
        x0, y0, x1, y1 = max(x - m, 0), max(y - m, 0), min(x + bw + m, w), min(y + bh + m, h)
        box = (x0, y0, x1 - x0, y1 - y0)
        return self._seed_in_box(
            frames[i], bins[i], self._residual(flow, i), box, self._seen(frames, i).animal
        )

    def _seed_in_box(self, frame, bins, residual, box: Box, animal: np.ndarray) -> np.ndarray:
        """A localiser seed: (H, W) bool mask of the animal in ``box`` given its class map ``animal``.

        What moves with the animal (its reflection, its wake) is in the box too and has its colours,
        but less class evidence. So the seed is also cut from the core alone (the part of it the class
        map is surest of, in the colours typical of that part). The core's mask is taken only when the
        evidence says that what it leaves out is not the animal: it keeps the pixels where the class
        map is surest (at least 85% of those over 0.7 of its peak), holds half the peak on average,
        and what it leaves out is big (a quarter of the animal or more: a reflection or wake, not a
        leg in other colours).
        """
        likely = animal >= 0.5 if self.seed_from_map else None
        if not self.core_quantile:
            return self._first(frame, bins, residual, box, likely=likely)
        with ThreadPoolExecutor(1, thread_name_prefix="grabcut-core") as side:  # the two cuts side by side
            cut = side.submit(self._first, frame, bins, residual, box, animal)
            plain = self._first(frame, bins, residual, box, likely=likely)
            core = cut.result()
        surest = plain & (animal >= 0.7)
        if (
            not surest.any()
            or (core & surest).sum() < 0.85 * surest.sum()
            or (plain & ~core).sum() < 0.25 * core.sum()
            or animal[core].mean() < 0.5
        ):
            return plain
        return core

    def _due(self, i: int, t: int, mask: np.ndarray, prior: np.ndarray) -> bool:
        """Check the tracked mask against the localiser on keyframes (those `_start` already looked
        at: no new look), and whenever it shrinks or vanishes."""
        if i % self.key_every == 0 or i == t - 1:
            return True
        area, before = int(mask.sum()), int(prior.sum())
        if before == 0:  # lost (out of frame, hidden): look for it again on every frame
            return True
        return area < 0.5 * before

    def _reseed(self, frames, bins, flow, i: int, mask, hist_fg, hist_bg) -> np.ndarray | None:
        """A fresh mask for frame i when the tracked one disagrees with what the localiser sees and
        the fresh one has the animal's colours (seed frame's model), else None."""
        score, ev = self._fused(frames, flow, i)
        region, _ = main_region(score)
        if not region.any():
            return None
        near = cv2.dilate(mask.astype(np.uint8), cues.disk(max(mask.shape) // 40)).astype(bool)
        agreement = float((region & near).sum() / region.sum())
        if mask.any() and agreement >= self.min_agreement:
            return None
        new = self._seed(frames, bins, flow, i)
        if not new.any():
            return None
        # the localiser also fires on empty backgrounds (grass "looks like" a field with a dog in
        # it): a new seed must look like the animal tracked so far
        p = cues.colour_probability(bins[i], hist_fg, hist_bg)
        fresh = float(p[new].mean())
        if fresh < self.reseed_colour or (mask.any() and fresh <= float(p[mask].mean())):
            return None  # a tracked mask is replaced only by one that looks more like the animal
        return new

    def _report(self, how: list[str], s: int) -> dict:
        """What `video show` tells: how each frame got its mask and what the localiser saw."""
        seen = self._evidence
        probs: dict[int, float] = {}
        for ev in seen.values():
            for c, p in ev.classes:
                probs[c] = probs.get(c, 0.0) + p / len(seen)
        top = sorted(probs.items(), key=lambda kv: -kv[1])[:3]
        return {
            "seeding": how,
            "seed_frame": s,
            "seed_ranking": [int(k) for k in self._seed_ranking],
            "localised_frames": sorted(seen),
            "animal_classes": [
                {"index": c, "name": class_name(c), "probability": round(p, 3)} for c, p in top
            ],
            "animals_seen": int(self._animals_seen),
        }

    # -- steps ------------------------------------------------------------------------------------

    def _first(
        self,
        frame: np.ndarray,
        bins: np.ndarray,
        residual: np.ndarray,
        box: Box,
        animal: np.ndarray | None = None,
        likely: np.ndarray | None = None,
    ) -> np.ndarray:
        """Frame mask from a box: the box's moving, box-coloured pixels seed GrabCut. ``animal``: the
        class map; the seed keeps its core, its pixels at or over the map's ``core_quantile`` among
        them whose colours are more typical of the core than of the frame outside the box.
        ``likely``: (H, W) bool, pixels GrabCut starts as probably the animal too (in the box)."""
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
        if animal is not None:
            core = seed & (animal >= np.quantile(animal[seed], self.core_quantile))
            # of those, the colours more typical of the core than of the frame outside the box (dark
            # water under a swan is in the core too, but also all around it)
            p_core = cues.colour_probability(
                bins, cues.colour_histogram(bins, core), cues.colour_histogram(bins, ~inbox)
            )
            seed = cues.largest_components(core & (p_core > 0.5))
        # a hand-drawn box often cuts off a paw or an ear: a margin around it is only "probably"
        # background, so the animal's colours do not end up in GrabCut's background model
        x, y, bw, bh = box
        m = round(self.box_margin * max(bw, bh))
        trimap = np.full((h, w), cv2.GC_BGD, np.uint8)
        trimap[cues.box_mask((h, w), (x - m, y - m, bw + 2 * m, bh + 2 * m))] = cv2.GC_PR_BGD
        if likely is not None:
            trimap[inbox & likely] = cv2.GC_PR_FGD
        trimap[seed] = cv2.GC_PR_FGD
        out = _clean(_grabcut(frame, trimap, self.first_iterations), seed)
        # a box that cuts through the animal puts its colours in the background model and GrabCut
        # can drop it all: the seed itself is a better start than nothing
        return out if out.sum() >= 0.3 * seed.sum() else _clean(seed, seed)

    def _track(
        self, frame, bins, prior, residual, hist_fg, hist_bg, gate: float, unreliable=None, models=None
    ) -> np.ndarray:
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
        p_motion = cues.motion_probability(residual, window)
        if unreliable is not None:  # what only seems to move (ripples) is no evidence of the animal
            p_motion = np.where(_closed(unreliable), 0.0, p_motion)
        cue = np.sqrt(p_colour * p_motion)
        # a limb the flow lost is taken back when it moves unlike the camera and looks like the animal
        grow = prior | (window & (cue > 0.5) & (p_first > gate))
        around = cv2.dilate(grow.astype(np.uint8), cues.disk(self.band * size)).astype(bool) & window
        sure = (
            cv2.erode(prior.astype(np.uint8), cues.disk(0.12 * size)).astype(bool)
            & (p_colour > 0.3)
            & ((cue > 0.5) | (self.hold_still & (p_first > 0.5)))
        )
        trimap = np.full((h, w), cv2.GC_BGD, np.uint8)
        trimap[around] = cv2.GC_PR_BGD
        trimap[grow] = cv2.GC_PR_FGD
        # drift: propagated pixels that neither look like frame 0's animal nor move/look like this frame's
        trimap[prior & (p_first < self.demote) & ((p_motion < 0.5) | (p_local < 0.5))] = cv2.GC_PR_BGD
        trimap[sure] = cv2.GC_FGD
        # GrabCut shaves off thin parts (legs, tails) whose colours the background shares; off by
        # default: next to water the animal's reflection and wake move with it and would be locked in
        if self.keep_moving:
            near = cv2.dilate(prior.astype(np.uint8), cues.disk(self.band * size)).astype(bool)
            trimap[near & (p_motion > 0.9) & (p_first > max(gate, self.keep_colour))] = cv2.GC_FGD
        return _clean(_grabcut(frame, trimap, self.iterations, models), prior)


def _grabcut(
    frame: np.ndarray,
    trimap: np.ndarray,
    iterations: int,
    models: list | None = None,
    margin: int | None = None,
) -> np.ndarray:
    """GrabCut on the window around the non-definite-background part of ``trimap``; (H, W) bool.
    ``models``: a list, empty or holding the (background, foreground) colour models a cut left
    (the previous frame's, when tracking): the cut starts from them instead of k-means, and leaves
    its own there. ``margin``: the window's margin in pixels (default: half the part's larger side
    and 8)."""
    h, w = trimap.shape
    box = cues.box_of(trimap != cv2.GC_BGD)
    if box is None:
        return np.zeros((h, w), bool)
    x, y, bw, bh = box
    # enough definite background around for a fair background model
    m = max(bw, bh) // 2 + 8 if margin is None else margin
    x0, y0, x1, y1 = max(x - m, 0), max(y - m, 0), min(x + bw + m, w), min(y + bh + m, h)
    sub = np.ascontiguousarray(trimap[y0:y1, x0:x1])
    fg_labels = (cv2.GC_FGD, cv2.GC_PR_FGD)
    if not np.isin(sub, fg_labels).any() or np.isin(sub, fg_labels).all():
        return np.isin(trimap, fg_labels)
    img = np.ascontiguousarray(frame[y0:y1, x0:x1, ::-1])  # OpenCV's GrabCut is BGR
    bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    start = cv2.GC_INIT_WITH_MASK
    if models:  # the colour models the previous frame's cut ended with, instead of k-means
        bgd[:], fgd[:] = models
        start = cv2.GC_EVAL
    if models is not None:
        models.clear()
    # GrabCut starts its colour models with k-means on OpenCV's random numbers (a stream per
    # thread): seeded at each cut, a mask depends on its inputs alone, not on the thread that makes
    # it or on the cuts made before
    cv2.setRNGSeed(0)
    try:
        cv2.grabCut(img, sub, None, bgd, fgd, iterations, start)
        if models is not None:
            models.extend((bgd, fgd))
    except cv2.error:  # a GMM with too few samples of one class: keep the trimap's own guess
        pass
    out = np.zeros((h, w), bool)
    out[y0:y1, x0:x1] = np.isin(sub, fg_labels)
    return out


def _clean(mask: np.ndarray, reference: np.ndarray) -> np.ndarray:
    return cues.fill_holes(cues.largest_components(mask, reference=reference))


def _check_box(box: Box, w: int, h: int, frame: int = 0) -> Box:
    x, y, bw, bh = (int(round(v)) for v in box)
    x0, y0, x1, y1 = max(x, 0), max(y, 0), min(x + bw, w), min(y + bh, h)
    if bw <= 0 or bh <= 0 or x1 - x0 < 4 or y1 - y0 < 4:
        raise UsageError(
            f"--box {x},{y},{bw},{bh} does not cover a part of the {w}x{h} frame {frame}",
            hint="give x,y,w,h in pixels of the original video, around the animal in frame --box-frame",
        )
    return x0, y0, x1 - x0, y1 - y0


def _closed(mask: np.ndarray) -> np.ndarray:
    """Small gaps closed: unreliable flow comes in speckles over a rippling surface."""
    return cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_CLOSE, cues.disk(2)).astype(bool)


def resize_flows(flow, w: int, h: int, like=None):
    """(N, H, W, 2) flow -> (N, h, w, 2), displacements rescaled to the new pixel size (in memory,
    or in a scratch file when ``like`` is not a NumPy array)."""
    out = working(like if like is not None else flow, len(flow), (h, w, 2), np.float32)
    for i in range(len(flow)):
        out[i] = resize_flow(np.asarray(flow[i], np.float32), w, h)
    return out


class _Bins:
    """The frames' Lab colour bins (`cues.lab_bins`), each made when first asked for (by the tracker
    or its helper thread, a frame ahead) and kept (a lazy video's in a scratch file)."""

    def __init__(self, frames) -> None:
        self._frames = frames
        self._bins = working(frames, len(frames), frames.shape[1:3], np.int32)
        self._made = np.zeros(len(frames), bool)

    def __getitem__(self, i: int) -> np.ndarray:
        if not self._made[i]:  # two threads may both make it: the same bins
            self._bins[i] = cues.lab_bins(self._frames[i])
            self._made[i] = True
        return self._bins[i]


class _Stopped(Exception):
    """Ends a tracking direction whose other direction failed."""


class _Seen:
    """The localiser's looks by frame (`Evidence`), as a dict: for a lazy video the class maps
    wait in a scratch file, so a long video holds only their summaries."""

    def __init__(self, frames) -> None:
        self._lazy = not isinstance(frames, np.ndarray)
        self._items: dict[int, Evidence] = {}
        self._maps: ScratchArray | None = None
        self._where: dict[int, int] = {}
        self._lock = threading.Lock()
        self._making: dict[int, threading.Event] = {}

    def get(self, i: int, look: Callable[[], Evidence]) -> Evidence:
        """Frame i's look, taken with ``look()`` unless it is here (or being taken: then awaited;
        the cache serves two threads)."""
        with self._lock:
            taking = self._making.get(i)
            if i not in self._items and taking is None:
                self._making[i] = threading.Event()
        if taking is not None:
            taking.wait()
        if i in self._items:
            return self[i]
        if taking is not None:  # the other thread failed to take it
            return self.get(i, look)
        try:
            ev = look()
            with self._lock:
                self[i] = ev
        finally:
            with self._lock:
                self._making.pop(i).set()
        return self[i]

    def __contains__(self, i: int) -> bool:
        return i in self._items

    def __len__(self) -> int:
        return len(self._items)

    def __iter__(self):
        return iter(self._items)

    def __setitem__(self, i: int, ev: Evidence) -> None:
        if not self._lazy:
            self._items[i] = ev
            return
        if self._maps is None:
            self._maps = ScratchArray(0, ev.animal.shape, ev.animal.dtype)
        self._where[i] = len(self._maps)
        self._maps.append(ev.animal)
        self._items[i] = dataclasses.replace(ev, animal=np.zeros((0, 0), ev.animal.dtype))

    def __getitem__(self, i: int) -> Evidence:
        ev = self._items[i]
        if not self._lazy:
            return ev
        return dataclasses.replace(ev, animal=self._maps[self._where[i]])  # type: ignore[index]

    def values(self):
        """Summaries of the looks (their class maps left out), by frame (whichever direction of the
        tracking looked first: the report's sums come out the same)."""
        return [self._items[i] for i in sorted(self._items)]
