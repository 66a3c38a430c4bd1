"""A segmenter that learns each video: a pixel classifier trained on the video's own sure pixels.

The classical tracker (`zooctl.video.grabcut`) decides each frame from its neighbour's mask, its
colour histograms and the flow; where it leaks onto the background or drops a part of the animal
on some frames, nothing in those frames says it was wrong. This segmenter runs the tracker first,
then learns from the whole video what its animal and its background look like, and decides every
frame again with that knowledge:

1. features: the shipped EfficientNet-Lite0 (numpy, `zooctl.embed.effnet_numpy`, ImageNet weights,
   nothing downloaded) on every ``feature_every``-th frame, its stride-8, -16 and -32 stages
   sampled on the stride-8 grid (what a part looks like at three scales), and the class activation
   map of its animal classes (as `zooctl.video.localise` makes it);
2. sure labels from the tracker's masks: cells deep inside a mask are the animal, cells far outside
   it are background, the band around the outline is left out; a frame the tracker left empty
   teaches background only where the class map sees no animal;
3. a logistic regression on a sample of those cells (the classes in their natural proportion, L2),
   fitted per video by Newton's method, and a colour model (Lab histograms of the sure pixels of
   every frame): nothing but the video itself is learned from, so no weights ship;
4. every frame gets the classifier's log-odds (frames between two looks: their neighbours' carried
   along the flow), plus the colour model's, plus (with ``motion_weight``) a motion model's (the same
   histograms of how far each pixel moves against the camera: an animal walking over still ground,
   or the ground between its legs), plus a prior for the tracker's own mask; the
   connected part over even odds that holds the most probability is the animal. A frame the tracker
   left empty (the animal hidden or out of frame) stays empty.

What it does not do: a mask that has slid off the animal onto the background for many frames
teaches the classifier that background, and is kept (measured in BENCHMARKS.md, Video store).
Works on CPU, offline.
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

from ..errors import InputError
from . import cues
from .flow import warp
from .scratch import working

Progress = Callable[[int, int], None]

# bins of the motion model: log-spaced in hundredths of the frame's width, up to about 13
MOTION_BINS = 16
# the motion model's smoothing, a share of each class's mean count a bin (`log_odds`)
MOTION_SHARE = 0.05

# last block of the EfficientNet-Lite0 stages whose outputs are sampled (stride 8, 16, 32)
FEATURE_BLOCKS = {4: 8, 10: 16, 15: 32}


class FeatureNet:
    """Multi-scale features of frames from the shipped ImageNet EfficientNet-Lite0 (numpy).

    ``width``: network input width (height from the frame's aspect; multiples of 32).
    ``features(frame)`` -> ((h/8, w/8, C) float32 features, (h/8, w/8) float32 animal map).
    """

    def __init__(self, width: int = 320, top: int = 5) -> None:
        from ..embed.effnet_arch import weights_path
        from ..embed.effnet_numpy import load_numpy_model

        self.model = load_numpy_model(weights_path())
        self.width = width
        self.top = top

    def input_size(self, w: int, h: int) -> tuple[int, int]:
        iw = max(32, round(self.width / 32) * 32)
        ih = max(32, round(self.width * h / w / 32) * 32)
        return iw, ih

    def features(self, frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        from ..embed.effnet_arch import INPUT_MEAN, INPUT_STD
        from .localise import ANIMAL_CLASSES

        fh, fw = frame.shape[:2]
        iw, ih = self.input_size(fw, fh)
        x = cv2.resize(frame, (iw, ih), interpolation=cv2.INTER_AREA if iw < fw else cv2.INTER_LINEAR)
        x = (x.astype(np.float32)[None] - INPUT_MEAN) / INPUT_STD
        m = self.model
        h = m._relu6(m._apply_stem(x))
        taken = []
        for k, b in enumerate(m.blocks):
            y = h
            if b.expand is not None:
                y = m._relu6(m._apply_pointwise(y, b.expand))
            y = m._relu6(m._apply_depthwise(y, b.depthwise))
            y = m._apply_pointwise(y, b.project)
            if b.skip:
                y += h
            h = y
            if k in FEATURE_BLOCKS:
                taken.append(h[0])
        head = m._relu6(m._apply_pointwise(h, m.head))[0]
        gh, gw = ih // 8, iw // 8
        parts = [_on_grid(f, s, gw, gh) for f, s in zip(taken, FEATURE_BLOCKS.values())]
        feats = np.concatenate(parts, -1)
        # the class activation map of the frame's top animal classes (as the localiser makes it)
        logits = head.mean((0, 1)) @ m.fc_weight + m.fc_bias
        p = np.exp(logits - logits.max())
        p = p[:ANIMAL_CLASSES] / p.sum()
        top = np.argsort(p)[::-1][: self.top]
        cam = head @ (m.fc_weight[:, top] @ (p[top] / max(float(p[top].sum()), 1e-12)))
        cam = _on_grid(cam.astype(np.float32)[..., None], 32, gw, gh)[..., 0]
        cam -= np.median(cam)
        peak = float(cam.max())
        cam = np.clip(cam / peak, 0.0, 1.0) if peak > 1e-6 else np.zeros_like(cam)
        return feats.astype(np.float32), cam.astype(np.float32)


def _on_grid(f: np.ndarray, stride: int, gw: int, gh: int) -> np.ndarray:
    """(h, w, C) map of a stride-``stride`` stage -> (gh, gw, C) on the stride-8 grid.

    The network pads symmetrically, so its cell i is centred on input pixel ``stride * i`` (not on
    the middle of its block as a plain resize assumes): stride-8 cell j samples stride-s cell
    ``8 j / s``."""
    if stride == 8 and f.shape[:2] == (gh, gw):
        return np.ascontiguousarray(f)
    mx = np.broadcast_to(np.arange(gw, dtype=np.float32) * 8 / stride, (gh, gw))
    my = np.broadcast_to((np.arange(gh, dtype=np.float32) * 8 / stride)[:, None], (gh, gw))
    mx, my = np.ascontiguousarray(mx), np.ascontiguousarray(my)
    # OpenCV remaps at most 128 channels at a time
    chunks = [
        cv2.remap(
            np.ascontiguousarray(f[..., c : c + 128]),
            mx,
            my,
            cv2.INTER_LINEAR,
            borderMode=cv2.BORDER_REPLICATE,
        )
        for c in range(0, f.shape[-1], 128)
    ]
    return np.concatenate([c if c.ndim == 3 else c[..., None] for c in chunks], -1)


def grid_to_pixels(grid: np.ndarray, w: int, h: int, input_size: tuple[int, int]) -> np.ndarray:
    """(gh, gw) float32 map on the stride-8 grid of an ``input_size`` (iw, ih) network input ->
    (h, w) at a frame's pixels (cell j is centred on input pixel 8 j)."""
    iw, ih = input_size
    mx = ((np.arange(w, dtype=np.float32) + 0.5) * iw / w - 0.5) / 8
    my = ((np.arange(h, dtype=np.float32) + 0.5) * ih / h - 0.5) / 8
    mx, my = np.broadcast_to(mx, (h, w)), np.broadcast_to(my[:, None], (h, w))
    return cv2.remap(
        np.ascontiguousarray(grid, np.float32),
        np.ascontiguousarray(mx),
        np.ascontiguousarray(my),
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REPLICATE,
    )


def fit_logistic(
    x: np.ndarray, y: np.ndarray, weight: np.ndarray, l2: float = 1.0, steps: int = 8
) -> tuple[np.ndarray, float]:
    """Weighted L2-regularised logistic regression by Newton's method.

    ``x`` (N, D) float32 standardised features, ``y`` (N,) 0/1, ``weight`` (N,) sample weights
    (summing to N keeps ``l2`` on the scale of one sample each) -> (w (D,), bias).
    """
    n, d = x.shape
    xb = np.concatenate([x, np.ones((n, 1), np.float32)], 1).astype(np.float32)
    beta = np.zeros(d + 1)
    reg = np.full(d + 1, l2)
    reg[-1] = 0.0
    for _ in range(steps):
        z = np.clip(xb @ beta.astype(np.float32), -30, 30).astype(np.float64)
        p = 1.0 / (1.0 + np.exp(-z))
        g = xb.T @ (weight * (p - y)).astype(np.float32) + reg * beta
        s = weight * p * (1 - p)
        hess = ((xb * s[:, None].astype(np.float32)).T @ xb).astype(np.float64) + np.diag(reg + 1e-6)
        step = np.linalg.solve(hess, g)
        beta -= step
        if np.abs(step).max() < 1e-4:
            break
    return beta[:-1], float(beta[-1])


def cell_labels(
    mask: np.ndarray, animal: np.ndarray, band: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sure cells and pixels of one frame from its tracked mask (H, W) bool and its animal map
    (gh, gw) on the stride-8 grid.

    -> (animal cells, background cells) (gh, gw) bool, (animal pixels, background pixels) (H, W)
    bool. Sure animal: inside the mask shrunk by ``band`` of its size; sure background: outside it
    grown by twice that. A frame without a mask teaches only background, and only where the animal
    map sees no animal.
    """
    gh, gw = animal.shape
    if not mask.any():
        none = np.zeros(mask.shape, bool)
        return np.zeros((gh, gw), bool), animal < 0.5, none, none
    r = max(1.0, band * float(np.sqrt(mask.sum())))
    # distances to the other side (linear in the pixels, where a large disk's erosion is not)
    m8 = mask.astype(np.uint8)
    inner = cv2.distanceTransform(m8, cv2.DIST_L2, 3) > r
    outer = cv2.distanceTransform(1 - m8, cv2.DIST_L2, 3) <= 2 * r
    fi = cv2.resize(inner.astype(np.float32), (gw, gh), interpolation=cv2.INTER_AREA)
    fo = cv2.resize(outer.astype(np.float32), (gw, gh), interpolation=cv2.INTER_AREA)
    return fi > 0.99, fo < 0.01, inner, ~outer


class SelfTrainedSegmenter:
    """``segment(frames, box, progress, flow, box_frame) -> (T, H, W) bool``; see the module docstring.

    ``feature_width``: the network's input width. ``feature_every``: frames between two the network
    looks at (the frames between get their neighbours' classifier output carried along the flow).
    ``band``: how far inside (and twice as far outside) the tracked mask a pixel must be to count as
    sure, as a fraction of the animal's size. ``deep_weight``, ``colour_clip``, ``motion_weight``,
    ``motion_clip``, ``prior_weight``: the per-pixel log-odds that the animal is there is
    ``deep_weight`` x the classifier's, plus the colour model's (clipped to +-``colour_clip``), plus
    ``motion_weight`` x the motion model's (`motion_bins`; clipped to +-``motion_clip``), plus
    ``prior_weight`` inside the tracked mask and minus it outside. ``l2``: the classifier's
    regularisation; ``max_samples``: sure cells it is fitted on at most (drawn evenly over the
    frames, repeatably). Other options go to the tracker (`zooctl.video.grabcut.GrabCutTracker`).
    ``report``: the tracker's, with ``self_training`` added (cells learned from, frames looked
    at, share of mask pixels changed).
    """

    name = "selftrain"
    uses_flow = True

    def __init__(
        self,
        feature_width: int = 320,
        feature_every: int = 3,
        band: float = 0.1,
        deep_weight: float = 0.5,
        colour_clip: float = 5.0,
        prior_weight: float = 2.0,
        motion_weight: float = 0.0,
        motion_clip: float = 3.0,
        l2: float = 1.0,
        max_samples: int = 6000,
        **tracker_options,
    ) -> None:
        from ..errors import UsageError
        from .grabcut import GrabCutTracker

        if feature_every < 1:
            raise UsageError(f"feature_every must be at least 1, got {feature_every}")
        if feature_width < 32:
            raise UsageError(f"feature_width must be at least 32 pixels, got {feature_width}")
        if max_samples < 10:
            raise UsageError(f"max_samples must be at least 10, got {max_samples}")
        if motion_weight < 0 or motion_clip <= 0:
            raise UsageError(
                f"motion_weight must be at least 0 and motion_clip over 0, got {motion_weight} and {motion_clip}"
            )
        self.tracker = GrabCutTracker(**tracker_options)
        self.feature_width = feature_width
        self.feature_every = feature_every
        self.band = band
        self.deep_weight = deep_weight
        self.colour_clip = colour_clip
        self.prior_weight = prior_weight
        self.motion_weight = motion_weight
        self.motion_clip = motion_clip
        self.l2 = l2
        self.max_samples = max_samples
        self._net: FeatureNet | None = None
        self.report: dict = {}

    def flow_size(self, w: int, h: int) -> tuple[int, int]:
        """(w, h) the tracker (and this segmenter) works at: the flow it reads, at that size."""
        return self.tracker.flow_size(w, h)

    def segment(
        self,
        frames: np.ndarray,
        box=None,
        progress: Progress | None = None,
        flow=None,
        box_frame: int = 0,
    ) -> np.ndarray:
        """(T, H, W, 3) uint8 RGB frames, optional box on frame ``box_frame`` -> (T, H, W) bool masks."""
        t = len(frames)
        flow, tracked = track(self.tracker, frames, box, progress, flow, box_frame, "selftrain")
        self.report = dict(self.tracker.report)
        small, prior = at_working_size(frames, tracked, flow.forward.shape[1:3])
        masks = self.relabel(small, prior, flow, lambda d: progress(t + d, 2 * t) if progress else None)
        if masks is None:  # nothing sure to learn from: the tracker's masks stand
            return tracked
        return at_frame_size(masks, frames)

    # -- the steps --------------------------------------------------------------------------------

    def relabel(self, frames, prior, flow, progress: Callable[[int], None], seen=None, net=None, moving=None):
        """Frames and tracked masks at the working size -> new masks (T, h, w) bool, or None when the
        tracked masks hold no sure animal pixel. ``seen``: {frame index: `FeatureNet.features` of
        that frame} already computed by ``net`` (a `FeatureNet` of this ``feature_width``), reused.
        ``moving``: (T, h, w) uint8 `video_motion_bins` of these frames, when already taken."""
        t, h, w = frames.shape[:3]
        seen = seen or {}
        if net is None or net.width != self.feature_width:
            if self._net is None or self._net.width != self.feature_width:
                self._net = FeatureNet(self.feature_width)
            net, seen = self._net, {}
        looked = sorted(set(range(0, t, self.feature_every)) | {t - 1})
        looked_at = {i: k for k, i in enumerate(looked)}
        iw, ih = net.input_size(w, h)
        grid = (ih // 8, iw // 8)
        feats = None
        samples: list[tuple[np.ndarray, float, float]] = []  # (features, label, weight)
        rng = np.random.default_rng(0)
        per_frame = max(self.max_samples // (2 * len(looked)), 1)
        bins = working(frames, t, (h, w), np.int32)
        hist_fg = np.zeros(cues.HIST_BINS**3)
        hist_bg = np.zeros(cues.HIST_BINS**3)
        if not self.motion_weight:
            moving = None
        elif moving is None:
            moving = video_motion_bins(frames, flow)
        motion_fg, motion_bg = np.zeros(MOTION_BINS), np.zeros(MOTION_BINS)
        steps, done = len(looked) + t, 0
        no_map = np.zeros(grid, np.float32)
        for i in range(t):
            mask = np.asarray(prior[i], bool)
            if i in looked_at:
                f, animal = seen[i] if i in seen else net.features(frames[i])
                if feats is None:
                    feats = working(frames, len(looked), (*grid, f.shape[-1]), np.float16)
                feats[looked_at[i]] = f
            else:
                animal = no_map
            fg, bg, fg_px, bg_px = cell_labels(mask, animal, self.band)
            if i in looked_at:
                for sure, label in ((fg, 1.0), (bg, 0.0)):
                    # a sample of the frame's sure cells, weighted back to their number (the classes
                    # keep their natural proportion)
                    idx = np.flatnonzero(sure)
                    if len(idx) > per_frame:
                        idx = rng.choice(idx, per_frame, replace=False)
                    if len(idx):
                        samples.append((f.reshape(-1, f.shape[-1])[idx], label, sure.sum() / len(idx)))
                done += 1
            bins[i] = cues.lab_bins(frames[i])
            hist_fg += np.bincount(bins[i][fg_px], minlength=cues.HIST_BINS**3)
            hist_bg += np.bincount(bins[i][bg_px], minlength=cues.HIST_BINS**3)
            if moving is not None:
                bins_i = np.asarray(moving[i])
                motion_fg += np.bincount(bins_i[fg_px], minlength=MOTION_BINS)
                motion_bg += np.bincount(bins_i[bg_px], minlength=MOTION_BINS)
            done += 1
            progress(t * done // (2 * steps))
        n_fg = sum(len(x) for x, label, _ in samples if label)
        n_bg = sum(len(x) for x, label, _ in samples if not label)
        self.report["self_training"] = {
            "animal_cells": int(n_fg),
            "background_cells": int(n_bg),
            "frames_looked_at": len(looked),
        }
        if n_fg < 2 or n_bg < 2:
            return None
        x = np.concatenate([x for x, _, _ in samples]).astype(np.float32)
        y = np.concatenate([np.full(len(x), label) for x, label, _ in samples])
        weight = np.concatenate([np.full(len(x), wt) for x, _, wt in samples])
        weight *= len(weight) / weight.sum()
        mu, sd = x.mean(0), x.std(0) + 1e-3
        wt, bias = fit_logistic((x - mu) / sd, y, weight, l2=self.l2)
        wt = (wt / sd).astype(np.float32)  # on the raw features
        bias = float(bias - mu @ wt)
        colour = log_odds(hist_fg, hist_bg, self.colour_clip)
        motion = self.motion_weight * log_odds(motion_fg, motion_bg, self.motion_clip, MOTION_SHARE)
        deep = working(frames, t, (h, w), np.float32)
        for k, i in enumerate(looked):
            deep[i] = grid_to_pixels(np.asarray(feats[k], np.float32) @ wt + bias, w, h, (iw, ih))
        carry_between(deep, looked, flow)
        out = working(frames, t, (h, w), bool)
        changed = 0
        for i in range(t):
            p = np.asarray(prior[i], bool)
            if not p.any():  # the teacher saw no animal here (hidden, or out of frame): none is made up
                out[i] = False
                progress(t // 2 + t * (i + 1) // (2 * t))
                continue
            logit = (
                self.deep_weight * deep[i]
                + colour[bins[i]]
                + np.where(p, self.prior_weight, -self.prior_weight)
            )
            if moving is not None:
                logit += motion[moving[i]]
            out[i] = main_animal(logit)
            changed += int((out[i] != p).sum())
            progress(t // 2 + t * (i + 1) // (2 * t))
        self.report["self_training"]["changed"] = round(
            changed / max(int(sum(np.asarray(prior[i]).sum() for i in range(t))), 1), 4
        )
        return out


def log_odds(hist_fg: np.ndarray, hist_bg: np.ndarray, clip: float, share: float | None = None) -> np.ndarray:
    """Two (B,) histograms of the sure animal's and background's pixels -> (B,) float32 log-odds
    that a pixel in each bin is the animal, clipped to +-``clip``. Smoothed by one count a bin, or
    with ``share`` by ``share`` x the class's mean count a bin: a bin neither class was seen in
    then reads even odds, not the odds of the smaller class."""
    pad_fg = pad_bg = 1.0
    if share is not None:
        pad_fg, pad_bg = (max(share * h.sum() / len(h), 1e-6) for h in (hist_fg, hist_bg))
    fg = np.log((hist_fg + pad_fg) / (hist_fg.sum() + pad_fg * len(hist_fg)))
    bg = np.log((hist_bg + pad_bg) / (hist_bg.sum() + pad_bg * len(hist_bg)))
    return np.clip(fg - bg, -clip, clip).astype(np.float32)


def motion_bins(residual: np.ndarray) -> np.ndarray:
    """(h, w) motion residual of a frame in pixels (`VideoFlow.residual`) -> (h, w) uint8 bin (of
    `MOTION_BINS`) of each pixel's motion against the camera, in hundredths of the frame's width on
    a log scale: still, then finer steps for slow motion than for fast."""
    scaled = np.log1p(residual * np.float32(400.0 / residual.shape[1])) * 4
    return np.clip(scaled, 0, MOTION_BINS - 1).astype(np.uint8)


def video_motion_bins(frames, flow):
    """`motion_bins` of every frame of (T, h, w, 3) ``frames`` from their `VideoFlow` at that size
    -> (T, h, w) uint8, where ``frames`` is
    (`zooctl.video.scratch.working`)."""
    t, h, w = frames.shape[:3]
    out = working(frames, t, (h, w), np.uint8)
    for i in range(t):
        out[i] = motion_bins(flow.residual(i))
    return out


def track(
    tracker, frames, box, progress, flow, box_frame: int, who: str, alongside=None, working_frames=None
):
    """The tracker's masks of (T, H, W, 3) ``frames`` and the flow at its working size, for a
    segmenter that decides again after it (half of its ``progress``) -> (flow, tracked masks).

    ``working_frames``: the frames at the working size (INTER_AREA), when the caller has them.
    ``alongside(small, flow)``: work that needs the frames (``small``, (T, h, w, 3) uint8) and the
    flow at the working size but not the masks, run on a second thread while the tracker runs (which
    then takes ``small`` instead of downscaling the frames again); its error is raised here."""
    from concurrent.futures import ThreadPoolExecutor
    from functools import partial

    from .flow import DISFlow, VideoFlow, compute_video_flow
    from .grabcut import resize_flows

    t, h, w = frames.shape[:3]
    if t < 2:
        raise InputError(f"the {who} segmenter needs at least 2 frames (it uses motion)")
    sw, sh = tracker.flow_size(w, h)
    if flow is None:
        flow = compute_video_flow(DISFlow(tracker.flow_preset), np.asarray(frames))
    if tuple(flow.forward.shape[1:3]) != (sh, sw):
        flow = VideoFlow(
            *(resize_flows(f, sw, sh, frames) for f in (flow.forward, flow.backward)), None, None
        )
    run = partial(
        tracker.segment,
        frames,
        box=box,
        progress=(lambda d, n: progress(d, 2 * n)) if progress else None,
        flow=flow,
        box_frame=box_frame,
    )
    small = working_frames
    if alongside is None:
        return flow, run() if small is None else run(working_frames=small)
    if small is None:
        small = working(frames, t, (sh, sw, 3), np.uint8)
        for i in range(t):
            f = frames[i]
            small[i] = f if f.shape[:2] == (sh, sw) else cv2.resize(f, (sw, sh), interpolation=cv2.INTER_AREA)
    with ThreadPoolExecutor(1, thread_name_prefix=f"{who}-alongside") as pool:
        beside = pool.submit(alongside, small, flow)
        tracked = run(working_frames=small)
        beside.result()
    return flow, tracked


def at_working_size(frames, masks, size: tuple[int, int]):
    """(T, H, W, 3) frames and (T, H, W) bool masks -> both at ``size`` (h, w), the working size
    a segmenter decides again at: ((T, h, w, 3) uint8, (T, h, w) bool)."""
    t = len(frames)
    h, w = size
    small = working(frames, t, (h, w, 3), np.uint8)
    small_masks = working(frames, t, (h, w), bool)
    for i in range(t):
        f = frames[i]
        small[i] = f if f.shape[:2] == (h, w) else cv2.resize(f, (w, h), interpolation=cv2.INTER_AREA)
        m = np.asarray(masks[i], bool)
        small_masks[i] = (
            m
            if m.shape == (h, w)
            else cv2.resize(m.astype(np.float32), (w, h), interpolation=cv2.INTER_AREA) > 0.5
        )
    return small, small_masks


def at_frame_size(masks, frames, small=None, edge_radius: float = 0.0, edge_eps: float = 1e-3):
    """(T, h, w) bool masks at the working size -> at the (T, H, W) frames' size. With ``small``
    ((T, h, w, 3) uint8, the frames the masks were decided on) and ``edge_radius`` > 0, each along
    its frame's colour edges (`zooctl.video.guided.guided_upsample` with that radius and
    ``edge_eps``); else a linear upsample."""
    from .guided import guided_upsample
    from .scratch import Resized

    h, w = frames.shape[1:3]
    upsample = None
    if small is not None and edge_radius > 0:

        def upsample(i: int, m: np.ndarray) -> np.ndarray:
            return guided_upsample(m, np.asarray(small[i]), np.asarray(frames[i]), edge_radius, edge_eps)

    elif masks.shape[1:3] == (h, w):
        return masks
    if isinstance(frames, np.ndarray):
        if upsample is not None:
            return np.stack([upsample(i, np.asarray(m, bool)) for i, m in enumerate(masks)])
        return np.stack(
            [cv2.resize(m.astype(np.float32), (w, h), interpolation=cv2.INTER_LINEAR) > 0.5 for m in masks]
        )
    return Resized(masks, w, h, upsample)


def carry_between(values, looked: list[int], flow) -> None:
    """Fill ``values`` (T, h, w) in place at the frames not in ``looked`` (sorted, holding the first
    and last frame): the two nearest looked frames' values carried along the flow and blended by
    distance."""
    seen = set(looked)
    for i in range(len(values)):
        if i in seen:
            continue
        a, b = max(j for j in looked if j < i), min(j for j in looked if j > i)
        pa = values[a]
        for j in range(a, i):
            pa = warp(pa, flow.backward[j])
        pb = values[b]
        for j in range(b - 1, i - 1, -1):
            pb = warp(pb, flow.forward[j])
        values[i] = ((b - i) * pa + (i - a) * pb) / (b - a)


def main_animal(logit: np.ndarray) -> np.ndarray:
    """(H, W) log-odds -> (H, W) bool: the connected part over 0 that holds the most probability,
    its small holes filled."""
    m = logit > 0
    if not m.any():
        return m
    p = 1.0 / (1.0 + np.exp(-np.clip(logit, -30, 30)))
    n, lab = cv2.connectedComponents(m.astype(np.uint8), connectivity=8)
    mass = np.bincount(lab.ravel(), weights=p.ravel(), minlength=n)
    mass[0] = 0.0
    return cues.fill_holes(lab == int(np.argmax(mass)))
