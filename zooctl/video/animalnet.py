"""``animalnet``: a small network that tells, per cell of a frame, whether an animal is there.

Input per frame, on the stride-8 grid of a ``FEATURE_WIDTH``-pixel-wide network input:
EfficientNet-Lite0's stride-8, -16 and -32 features and its animal class map (the shipped ImageNet
weights, `zooctl.video.selftrain.FeatureNet`, frozen), and the frame's motion unlike the camera's
(`motion_grid`: the flow's residual after the camera's homography, in hundredths of the frame's
width, squashed). Output: the log-odds that the cell is an animal, from a head of 1x1 and dilated
3x3 convolutions (`HEAD`), trained on synthetic composites (`zooctl.benchdata.composites`, by
`zooctl segment train`) and applied here in numpy (a video add stays torch-free).

Weights (``.npz``): the head's convolutions, the input standardisation and projection, and ``info`` (JSON: the
feature width, what the weights were trained on and its licence). Loaded from the path given,
else ``ZOOCTL_ANIMALNET_WEIGHTS``, else ``STORE/models/animalnet.npz`` when `zooctl segment train`
made it, else the shipped ones (``weights/animalnet.npz``: procedural animals only, see
``weights/README.md``).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError

FEATURE_WIDTH = 320
IN_CHANNELS = 40 + 112 + 320 + 1 + 1  # stride-8/16/32 features, class map, motion
# (name, kernel, dilation, out channels); every layer but the last is followed by a ReLU
HEAD = (
    ("c0", 1, 1, 64),
    ("c1", 3, 1, 32),
    ("c2", 3, 2, 32),
    ("c3", 3, 4, 32),
    ("c4", 3, 8, 32),
    ("out", 1, 1, 1),
)
# the switch's identity check: near the seed frame, the tracker's and the network's animal overlap
# at least this much (intersection over union) when they are one animal; a second animal beside the
# first only touches it (BENCHMARKS.md, Video store)
SAME_ANIMAL_IOU = 0.1
# a network part holds the tracked animal when at least this share of the tracked mask lies in it,
# the part widened by one cell of the network's grid (its outline is no finer)
HOLDS_TRACKED = 0.5
GRID_CELLS = FEATURE_WIDTH // 8  # cells across the network's input
# the relabelling's options where they differ from `selftrain`'s own defaults
RELABEL_DEFAULTS = {"prior_weight": 1.0, "motion_weight": 0.75}


def default_weights() -> Path:
    """Where `zooctl segment train` writes the weights by default: STORE/models/animalnet.npz."""
    from ..paths import default_store

    return default_store() / "models" / "animalnet.npz"


SHIPPED_WEIGHTS = Path(__file__).resolve().parent / "weights" / "animalnet.npz"


def weights_file(weights: str | Path | None = None) -> Path:
    """The weights to load: the argument, else ZOOCTL_ANIMALNET_WEIGHTS, else the store's
    (`default_weights`) when trained there, else the shipped ones (``weights/README.md``)."""
    chosen = weights or os.environ.get("ZOOCTL_ANIMALNET_WEIGHTS")
    if chosen is None:
        return default_weights() if default_weights().is_file() else SHIPPED_WEIGHTS
    p = Path(chosen).expanduser()
    if not p.is_file():
        raise InputError(
            f"animalnet weights {p} do not exist",
            hint="train them with `zooctl segment train` or point ZOOCTL_ANIMALNET_WEIGHTS at a weights .npz",
        )
    return p


def motion_grid(flow: np.ndarray | None, grid: tuple[int, int]) -> np.ndarray:
    """(H, W, 2) flow of a frame (or None: no motion known) -> (gh, gw) float32 in [0, 1): the
    motion the camera does not explain, in hundredths of the frame's width, squashed by tanh(x/2)."""
    if flow is None:
        return np.zeros(grid, np.float32)
    from .cues import background_motion_residual

    return residual_grid(background_motion_residual(np.ascontiguousarray(flow, np.float32)), grid)


def residual_grid(residual: np.ndarray, grid: tuple[int, int]) -> np.ndarray:
    """(H, W) pixels of motion the camera does not explain -> `motion_grid`'s (gh, gw) input."""
    gh, gw = grid
    r = residual * (100.0 / residual.shape[1])
    return np.tanh(cv2.resize(r, (gw, gh), interpolation=cv2.INTER_AREA) / 2.0).astype(np.float32)


def frame_inputs(net, frame: np.ndarray, flow: np.ndarray | None) -> np.ndarray:
    """(gh, gw, IN_CHANNELS) float32 input of one (H, W, 3) uint8 RGB frame; ``net`` a
    `zooctl.video.selftrain.FeatureNet` at ``FEATURE_WIDTH``; ``flow`` its flow to a neighbour."""
    feats, cam = net.features(frame)
    motion = motion_grid(flow, cam.shape)
    return np.concatenate([feats, cam[..., None], motion[..., None]], -1)


def motion_contrast(mask: np.ndarray, residual: np.ndarray) -> float:
    """How much more a region moves against the camera than what lies around it: the median of
    ``residual`` (H, W) inside ``mask`` (H, W) bool minus its median in a ring around the mask (0.15
    of the region's size wide, at least 3 pixels); 0 for a region under 20 pixels."""
    area = int(mask.sum())
    if area < 20:
        return 0.0
    r = max(int(0.15 * np.sqrt(area)), 3)
    grown = cv2.dilate(mask.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1,) * 2))
    ring = (grown > 0) & ~mask
    if not ring.any():
        return 0.0
    return float(np.median(residual[mask]) - np.median(residual[ring]))


def _conv(x: np.ndarray, w: np.ndarray, b: np.ndarray, dilation: int) -> np.ndarray:
    """(H, W, Cin) -> (H, W, Cout) 'same' convolution, zero padding; ``w`` (Cout, Cin, k, k)."""
    k = w.shape[-1]
    if k == 1:
        return x @ w[:, :, 0, 0].T + b
    h, wd = x.shape[:2]
    p = dilation * (k // 2)
    xp = np.pad(x, ((p, p), (p, p), (0, 0)))
    out = np.broadcast_to(b, (h, wd, w.shape[0])).copy()
    for i in range(k):
        for j in range(k):
            out += xp[i * dilation : i * dilation + h, j * dilation : j * dilation + wd] @ w[:, :, i, j].T
    return out


class AnimalNet:
    """The head with its weights: ``logits(inputs (gh, gw, IN_CHANNELS)) -> (gh, gw)`` log-odds."""

    def __init__(self, weights: str | Path | None = None) -> None:
        path = weights_file(weights)
        try:
            with np.load(path) as z:
                self.params = {k: z[k].astype(np.float32) for k in z.files if k != "info"}
                self.info = json.loads(str(z["info"]))
        except (OSError, KeyError, ValueError) as exc:
            raise InputError(f"{path} is not an animalnet weights file ({exc})") from None
        missing = [f"{n}.{p}" for n, *_ in HEAD for p in ("weight", "bias") if f"{n}.{p}" not in self.params]
        missing += [k for k in ("mean", "std", "proj") if k not in self.params]
        if missing:
            raise InputError(f"{path} is not an animalnet weights file (missing {', '.join(missing)})")
        p = self.params
        cin = IN_CHANNELS - 1
        shapes_ok = (
            p["mean"].shape == (cin,)
            and p["std"].shape == (cin,)
            and p["proj"].ndim == 2
            and p["proj"].shape[0] == cin
            and p["c0.weight"].ndim == 4
            and p["c0.weight"].shape[1] == p["proj"].shape[1] + 1
        )
        if not shapes_ok:
            raise InputError(f"{path} is not an animalnet weights file for this version (its shapes differ)")
        self.path = path

    def logits(self, inputs: np.ndarray) -> np.ndarray:
        p = self.params
        a = ((inputs[..., :-1] - p["mean"]) / p["std"]) @ p["proj"]
        x = np.concatenate([a, inputs[..., -1:]], -1)
        for k, (name, _, dilation, _) in enumerate(HEAD):
            x = _conv(x, self.params[f"{name}.weight"], self.params[f"{name}.bias"], dilation)
            if k < len(HEAD) - 1:
                x = np.maximum(x, 0.0)
        return x[..., 0]


class AnimalNetSegmenter:
    """``segment(frames, box, progress, flow, box_frame) -> (T, H, W) bool``: the `grabcut` tracker's
    masks, checked and decided again with the network, then learned per video as `selftrain` does.

    1. The tracker (`zooctl.video.grabcut.GrabCutTracker`) gives every frame a mask.
    2. Every ``feature_every``-th frame (and the last) the network gives each cell's log-odds that an
       animal is there, and its main animal (`zooctl.video.selftrain.main_animal`).
    3. A tracker that has slid onto the background keeps a region that moves with the camera, while
       the animal it lost moves against it: when, over the frames looked at, the median of the
       network's animal's `motion_contrast` minus the tracked mask's exceeds ``switch_motion``
       hundredths of the frame's width, the network's animal replaces the tracker's masks on every
       frame (the frames between looks then looked at too). ``switch_motion`` < 0: never. The
       switch must not take a second animal that merely moves more: when, on the looked frame
       nearest the tracker's seed frame, one of the network's parts is the tracked animal (they
       overlap, `same_part`), that part is followed from frame to frame (`follow_part`) and is the
       network's animal above; when none is, the network's main animal replaces the tracked masks
       only if the tracked region holds still against the camera (a tracker seeded on the
       background). A tracker can also hold only a piece of the animal (a tail fin, one band of a
       striped coat): when the network's part of the tracked animal (`same_part`, else the part
       that holds the tracked mask, `holding_part`), followed over the frames looked at, covers more
       than ``switch_cover`` times the tracked area (`part_cover`; < 0: never), that part replaces
       the tracker's masks the same way. Whether it does is decided on the whole frames, before
       any crop (below), which would hide the rest of the animal.
    4. Otherwise the tracked masks stand, or with ``net_weight`` > 0 are decided again from
       ``net_weight`` x the network's log-odds where it sees an animal (everywhere with ``erase``)
       plus ``prior_weight`` inside the tracked mask (minus it outside).
    5. With ``relabel``, `selftrain`'s per-video classifier and colour model, taught by those masks,
       decide every frame again (`SelfTrainedSegmenter.relabel`, on the features step 2 computed;
       ``relabel_options``: its ``band``, ``deep_weight``, ``prior_weight`` and ``motion_weight``
       (here 1 and 0.75 by default, chosen on the shared videos with the leave-one-out estimate
       beside them: BENCHMARKS.md), ...).
    6. A frame whose mask is under ``remnant`` times the video's median mask area and does not touch
       the frame's edge is stored empty: what a tracker leaves behind on the ground once the animal
       has left (an animal leaving or entering is cut by the edge). 0: never.
    With ``seeds`` > 1 (and no box), steps 1-6 run again from the keyframes the tracker ranks
    next, ``seeds`` in all, and the masks that agree most with the network's animal are kept when
    they agree clearly more than the first seed's (by over ``seeds_margin``; `_best_seed`): the
    seed frame, a near tie on many videos, can decide the whole video. A pass from another seed
    that meets the first pass's masks (`zooctl.video.grabcut.JOIN_IOU`) takes them from there on.
    7. With ``snap``, each frame is snapped to the animal's colours by a last GrabCut seeded by its
       mask, kept for the video only where that separates the mask's colours from its surroundings
       more (`zooctl.video.colour_snap.snap_video`, ``snap_gain`` its threshold): a blob of
       background the motion took for animal goes.
    8. The masks, decided at the working size, are brought to the frame's size along its colour
       edges (`zooctl.video.guided.guided_upsample`, a window of ``edge_radius`` times the working
       frame's larger side, regulariser ``edge_eps``); ``edge_radius`` 0: a linear upsample.

    Steps 2-6 run on the part of the frame the tracked animal keeps to, enlarged to the working size,
    when that part is at most half the frame's width and height (`decide_near`): a small or distant
    animal would otherwise cover a few cells of the network's and the relabelling's grid.

    ``flip``: the network (and the tracker's localiser) looks at each frame and its mirror image
    and averages the two, the mirror's log-odds mirrored back: a video and its mirror image get
    mirrored looks.

    ``weights``: the head's ``.npz`` (`weights_file`). Other options go to the tracker.
    ``report``: the tracker's, with ``animalnet`` added (weights, the motion margin measured, whether
    the network's masks replaced the tracker's, whether the identity check kept them out, the frames
    emptied as remnants, the part of the frame decided on, share of mask pixels changed) and
    ``colour_snap`` (`snap_video`'s report) when ``snap``.
    """

    name = "animalnet"
    uses_flow = True

    def __init__(
        self,
        weights: str | Path | None = None,
        feature_every: int = 3,
        switch_motion: float = 0.5,
        switch_cover: float = 1.16,
        relabel: bool = True,
        relabel_options: dict | None = None,
        net_weight: float = 0.0,
        prior_weight: float = 2.0,
        erase: bool = False,
        remnant: float = 0.1,
        edge_radius: float = 0.02,
        edge_eps: float = 1e-3,
        snap: bool = True,
        snap_gain: float | None = None,
        seeds: int = 2,
        seeds_margin: float = 0.005,
        flip: bool = False,
        **tracker_options,
    ) -> None:
        from ..errors import UsageError
        from .grabcut import GrabCutTracker

        if feature_every < 1 or seeds < 1:
            raise UsageError(f"feature_every and seeds must be at least 1, got {feature_every} and {seeds}")
        if not 0 <= edge_radius < 0.5 or edge_eps <= 0:
            raise UsageError(
                f"edge_radius must be in [0, 0.5) and edge_eps over 0, got {edge_radius} and {edge_eps}"
            )
        self.net = AnimalNet(weights)  # before the slow part: missing weights are refused at once
        self.tracker = GrabCutTracker(flip=flip, **tracker_options)
        self.flip = flip
        self.tracker.keep_looks = seeds > 1  # the other seeds' passes reuse the first's looks
        self.feature_every = feature_every
        self.switch_motion = switch_motion
        self.switch_cover = switch_cover
        self.relabel = relabel
        self.relabel_options = {**RELABEL_DEFAULTS, **(relabel_options or {})}
        self.net_weight = net_weight
        self.prior_weight = prior_weight
        self.erase = erase
        self.remnant = remnant
        self.edge_radius = edge_radius
        self.edge_eps = edge_eps
        self.snap = snap
        self.snap_gain = snap_gain
        self.seeds = seeds
        self.seeds_margin = seeds_margin
        self._features = None
        self.report: dict = {}

    def flow_size(self, w: int, h: int) -> tuple[int, int]:
        """(w, h) the tracker (and this segmenter) works at: the flow it reads, at that size."""
        return self.tracker.flow_size(w, h)

    def _feature_net(self):
        from .selftrain import FeatureNet

        if self._features is None:
            self._features = FeatureNet(int(self.net.info.get("feature_width", FEATURE_WIDTH)))
        return self._features

    def look(self, frame: np.ndarray, residual: np.ndarray) -> tuple[np.ndarray, tuple, np.ndarray]:
        """One (h, w, 3) frame at the working size and its (h, w) motion residual in pixels
        (`VideoFlow.residual`) -> ((h, w) network log-odds, the frame's `FeatureNet.features`,
        ``residual``)."""
        from .selftrain import grid_to_pixels

        h, w = frame.shape[:2]
        fnet = self._feature_net()

        def logits(frame, residual):
            feats, cam = fnet.features(frame)
            inputs = np.concatenate(
                [feats, cam[..., None], residual_grid(residual, cam.shape)[..., None]], -1
            )
            return grid_to_pixels(self.net.logits(inputs), w, h, fnet.input_size(w, h)), (feats, cam)

        out, features = logits(frame, residual)
        if self.flip:  # the features stay the frame's own: the relabelling learns on them
            mirror = (np.ascontiguousarray(a[:, ::-1]) for a in (frame, residual))
            out = (out + logits(*mirror)[0][:, ::-1]) / 2
        return out, features, residual

    def looks(self, small, flow) -> dict:
        """`look` at each frame `decide_video` looks at, of (T, h, w, 3) frames at the working size
        and their flow -> {frame: (log-odds, (float16 features, class map), residual motion)}."""
        t = len(small)
        out = {}
        for i in sorted(set(range(0, t, self.feature_every)) | {t - 1}):
            grid, (feats, cam), residual = self.look(small[i], flow.residual(i))
            out[i] = (grid, (feats.astype(np.float16), cam), residual)
        return out

    def evidence(self, frames, flow, progress=None) -> np.ndarray:
        """(T, h, w) float32 network log-odds at the flow's size for (T, H, W, 3) frames (every
        ``feature_every``-th looked at; the frames between carried along the
        flow); ``flow`` a `zooctl.video.flow.VideoFlow` at the working size."""
        from .scratch import working
        from .selftrain import carry_between

        t = len(frames)
        h, w = flow.forward.shape[1:3]
        looked = sorted(set(range(0, t, self.feature_every)) | {t - 1})
        out = working(frames, t, (h, w), np.float32)
        for k, i in enumerate(looked):
            frame = frames[i]
            if frame.shape[:2] != (h, w):
                frame = cv2.resize(frame, (w, h), interpolation=cv2.INTER_AREA)
            out[i] = self.look(frame, flow.residual(i))[0]
            if progress:
                progress(k + 1, len(looked))
        if len(looked) < t:
            carry_between(out, looked, flow)
        return out

    def decide(self, evidence: np.ndarray, tracked: np.ndarray) -> np.ndarray:
        """(h, w) network log-odds and (h, w) bool tracked mask -> (h, w) bool mask (step 4)."""
        from .selftrain import main_animal

        if self.net_weight <= 0:
            return tracked
        prior = np.where(tracked, self.prior_weight, -self.prior_weight)
        net = evidence if self.erase else np.maximum(evidence, 0.0)
        return main_animal(self.net_weight * net + prior)

    def decide_video(
        self,
        small,
        tracked,
        flow,
        progress=None,
        seed_frame: int | None = None,
        looks: dict | None = None,
        moving=None,
        part_switch: bool = True,
    ) -> np.ndarray:
        """Steps 2-6 on (T, h, w, 3) frames and (T, h, w) bool tracked masks at the working size and
        their flow -> (T, h, w) bool masks; sets ``report["animalnet"]``. ``seed_frame``: the frame
        the tracker started from (None: unknown, the switch then checks the main animal's motion
        only). ``looks``: `looks` already taken of these frames (by frame; the others are taken
        here). ``moving``: the relabelling's `selftrain.video_motion_bins` of these frames, when
        already taken. ``part_switch``: False when whether the tracked region is a piece of a
        larger animal was decided already (`decide_near`, on the whole frames)."""
        from . import cues
        from .scratch import working
        from .selftrain import SelfTrainedSegmenter, carry_between, main_animal

        t, h, w = small.shape[:3]
        looked = sorted(set(range(0, t, self.feature_every)) | {t - 1})
        ev = working(small, t, (h, w), np.float32)
        seen: dict[int, tuple] = {}
        margins, held, residuals = [], {}, {}
        looks = looks or {}
        for k, i in enumerate(looked):
            ev[i], f, residual = looks[i] if i in looks else self.look(small[i], flow.residual(i))
            seen[i] = (f[0].astype(np.float16), f[1])  # float16: as `relabel` keeps them
            animal = main_animal(ev[i])
            held[i], residuals[i] = motion_contrast(np.asarray(tracked[i], bool), residual), residual
            margins.append(motion_contrast(animal, residual) - held[i] if animal.any() else -np.inf)
            if progress:
                progress(k + 1, 2 * len(looked))
        still = float(np.median(list(held.values()))) * 100.0 / w
        moved = float(np.median(margins)) * 100.0 / w  # the network's main animal, whichever it is
        anchor = None
        if seed_frame is not None and 0 <= seed_frame < t:
            k0 = min(looked, key=lambda i: abs(i - seed_frame))
            anchor = same_part(animal_parts(ev[k0])[0], np.asarray(tracked[k0], bool))
        if anchor is not None:
            # the network's view of the tracked animal itself, followed from the seed frame: a second
            # animal, however fast, is never part of it
            margins = [
                motion_contrast(part, residuals[i]) - held[i] if part is not None else -np.inf
                for i, part in follow_part(lambda i: ev[i], looked, k0, anchor, carry_by_flow(flow))
            ]
        margin = float(np.median(margins)) * 100.0 / w
        switched = self.switch_motion >= 0 and margin > self.switch_motion
        if switched and anchor is None and seed_frame is not None:
            switched = still < 0.2 * self.switch_motion  # a tracker that started on the background
        whole, cover = None, None
        if seed_frame is not None and 0 <= seed_frame < t:
            whole, cover = tracked_part(lambda i: ev[i], looked, k0, tracked, flow)  # whole: anchor if any
        covered = (
            part_switch
            and not switched
            and self.switch_cover >= 0
            and cover is not None
            and cover > self.switch_cover
        )
        switched = switched or covered
        prior = working(small, t, (h, w), bool)
        if switched:
            for i in range(t):
                if i not in seen:
                    ev[i] = self.look(small[i], flow.residual(i))[0]
            if anchor is None and not covered:
                for i in range(t):
                    prior[i] = main_animal(ev[i])
            else:
                for i, part in follow_part(lambda i: ev[i], list(range(t)), k0, whole, carry_by_flow(flow)):
                    prior[i] = False if part is None else cues.fill_holes(part)
        else:
            if self.net_weight > 0 and len(looked) < t:
                carry_between(ev, looked, flow)
            for i in range(t):
                prior[i] = self.decide(ev[i], np.asarray(tracked[i], bool))
        masks = prior
        if self.relabel:
            fnet = self._feature_net()
            learner = SelfTrainedSegmenter(
                **{**self.relabel_options, "feature_width": fnet.width, "feature_every": self.feature_every}
            )
            relabelled = learner.relabel(
                small,
                prior,
                flow,
                (lambda d: progress(len(looked) + d * len(looked) // max(t, 1), 2 * len(looked)))
                if progress
                else (lambda d: None),
                seen=seen,
                net=fnet,
                moving=moving,
            )
            if relabelled is not None:
                masks = relabelled
            self.report["self_training"] = learner.report.get("self_training")
        dropped = drop_remnants(masks, self.remnant)
        changed = sum(int((np.asarray(masks[i]) != np.asarray(tracked[i], bool)).sum()) for i in range(t))
        total = sum(int(np.asarray(tracked[i], bool).sum()) for i in range(t))
        self.report["animalnet"] = {
            "weights": str(self.net.path),
            "motion_margin": round(margin, 3) if np.isfinite(margin) else None,
            "switch_motion": self.switch_motion,
            "network_replaced_tracker": bool(switched),
            "part_cover": None if cover is None else round(cover, 3),
            "switch_cover": self.switch_cover,
            "replaced_as_part": bool(covered),
            "identity_kept_tracker": bool(
                self.switch_motion >= 0 and moved > self.switch_motion and not switched
            ),
            "remnants_dropped": dropped,
            "relabelled": bool(self.relabel),
            "changed": round(changed / max(total, 1), 4),
        }
        if switched and "seeding" in self.report:  # `video show`'s per-frame account of the masks
            self.report["seeding"] = ["network"] * t
        if dropped and "seeding" in self.report:
            self.report["seeding"] = [
                "empty" if i in dropped else h for i, h in enumerate(self.report["seeding"])
            ]
        if progress:
            progress(2 * len(looked), 2 * len(looked))
        return masks

    def decide_near(
        self, small, tracked, flow, progress=None, seed_frame: int | None = None, **taken
    ) -> np.ndarray:
        """`decide_video` on the part of the frame the tracked animal keeps to, enlarged to the working
        size, when that part is at most half the frame's width and height (a small or distant animal,
        else the network and the relabelling see it on a few cells of their grid) and the tracked
        region is not a piece of a larger animal the network sees on the whole frames (``part_cover``
        over ``switch_cover``); the whole frame otherwise. Same arguments and result (``taken``:
        `decide_video`'s ``looks`` and ``moving``, of the whole frames, used when it decides on
        them); ``report["animalnet"]["crop"]``: the part (x, y, w, h) at the working size, or None."""
        from .flow import VideoFlow, resize_flow
        from .scratch import working

        t, h, w = small.shape[:3]
        box = _kept_to(tracked, w, h)
        cover = None
        if box is not None and self.switch_cover >= 0 and seed_frame is not None and 0 <= seed_frame < t:
            # a small tracked region may be a part of a larger animal, which a crop around it would
            # hide: whether it is one is decided on the whole frames
            if not taken.get("looks"):
                taken["looks"] = self.looks(small, flow)
            looks = taken["looks"]
            looked = sorted(looks)
            k0 = min(looked, key=lambda i: abs(i - seed_frame))
            cover = tracked_part(lambda i: looks[i][0], looked, k0, tracked, flow)[1]
            if cover is not None and cover > self.switch_cover:
                box = None
        if box is None:
            masks = self.decide_video(small, tracked, flow, progress, seed_frame, **taken)
            self.report["animalnet"]["crop"] = None
            return masks
        x, y, bw, bh = box
        scale = min(w / bw, h / bh)
        cw, ch = max(round(bw * scale), 1), max(round(bh * scale), 1)

        def up(a, interpolation):
            return cv2.resize(
                np.ascontiguousarray(a[y : y + bh, x : x + bw]), (cw, ch), interpolation=interpolation
            )

        # a long video's crop waits in scratch files, as its frames do
        frames_c = working(small, t, (ch, cw, 3), np.uint8)
        tracked_c = working(small, t, (ch, cw), bool)
        for i in range(t):
            frames_c[i] = up(small[i], cv2.INTER_LINEAR)
            tracked_c[i] = up(np.asarray(tracked[i], np.uint8), cv2.INTER_NEAREST) > 0
        parts = []
        for part in (flow.forward, flow.backward):
            out = working(small, len(part), (ch, cw, 2), np.float32)
            for i in range(len(part)):
                out[i] = resize_flow(
                    np.ascontiguousarray(np.asarray(part[i])[y : y + bh, x : x + bw]), cw, ch
                )
            parts.append(out)
        flow_c = VideoFlow(*parts, None, None)
        # whether the tracked region is part of a larger animal was decided on the whole frames
        got = self.decide_video(frames_c, tracked_c, flow_c, progress, seed_frame, part_switch=False)
        self.report["animalnet"]["part_cover"] = None if cover is None else round(cover, 3)
        masks = working(small, t, (h, w), bool)
        for i in range(t):
            m = np.zeros((h, w), bool)
            m[y : y + bh, x : x + bw] = (
                cv2.resize(np.asarray(got[i], np.float32), (bw, bh), interpolation=cv2.INTER_LINEAR) > 0.5
            )
            masks[i] = m
        self.report["animalnet"]["crop"] = [int(x), int(y), int(bw), int(bh)]
        return masks

    def segment(
        self, frames, box=None, progress=None, flow=None, box_frame: int = 0, working_frames=None
    ) -> np.ndarray:
        """(T, H, W, 3) uint8 RGB frames, optional box on frame ``box_frame`` -> (T, H, W) bool masks.
        ``working_frames``: the frames at `flow_size` (INTER_AREA), when the caller has them."""
        from .selftrain import at_frame_size, at_working_size, track, video_motion_bins

        t = len(frames)
        early: dict = {}

        def look_early(small, flow) -> None:  # the network's looks need no masks: taken while it tracks
            from ..store.videos import lower_thread_priority

            lower_thread_priority(5)  # the tracker first: these are needed only once it is done
            self._feature_net()
            early["small"], early["looks"] = small, self.looks(small, flow)
            if self.relabel and self.relabel_options.get("motion_weight"):
                early["moving"] = video_motion_bins(small, flow)

        flow, tracked = track(
            self.tracker,
            frames,
            box,
            progress,
            flow,
            box_frame,
            "animalnet",
            alongside=look_early,
            working_frames=working_frames,
        )
        self.report = dict(self.tracker.report)
        small, prior = at_working_size(early["small"], tracked, flow.forward.shape[1:3])
        masks = self.decide_near(
            small,
            prior,
            flow,
            (lambda d, n: progress(t + d * t // n, 2 * t)) if progress else None,
            seed_frame=self.tracker.report.get("seed_frame"),
            looks=early["looks"],
            moving=early.get("moving"),
        )
        if self.seeds > 1 and box is None:
            masks = self._best_seed(frames, small, flow, masks, early)
        self.tracker.forget()
        if self.snap:
            masks = self._snapped(small, masks)
        return at_frame_size(masks, frames, small, self.edge_radius, self.edge_eps)

    def _best_seed(self, frames, small, flow, masks, early):
        """Steps 1-6 again from the keyframes the tracker ranks next as seeds, ``seeds`` in all
        (`GrabCutTracker.start_at`: the first pass's looks and colour bins serve again); kept: the
        masks that agree most with the network's animal (`network_agreement`) if they agree more
        than the first seed's by over ``seeds_margin``, else the first seed's. The final masks are
        judged, not the tracked ones: whether the network's masks replace the tracker's (step 3)
        can differ by seed, and decides the video. ``report["seeds_tried"]``: {seed frame:
        agreement}."""
        from .selftrain import at_working_size, track

        looks = early["looks"]
        first = network_agreement(masks, looks)
        first_report = self.report
        best = (first, masks, first_report)
        tried = {int(self.report.get("seed_frame", -1)): round(first, 4)}
        for k in self.report.get("seed_ranking", [])[1 : self.seeds]:
            self.tracker.start_at = k
            try:
                _, tracked = track(
                    self.tracker, frames, None, None, flow, 0, "animalnet", working_frames=small
                )
            finally:
                self.tracker.start_at = None
            self.report = dict(self.tracker.report)
            prior = at_working_size(small, tracked, flow.forward.shape[1:3])[1]
            got = self.decide_near(small, prior, flow, seed_frame=k, looks=looks, moving=early.get("moving"))
            agreement = network_agreement(got, looks)
            tried[int(k)] = round(agreement, 4)
            if agreement > best[0]:
                best = (agreement, got, self.report)
        if best[0] - first <= self.seeds_margin:
            best = (first, masks, first_report)
        self.report = best[2]
        self.report["seeds_tried"] = tried
        return best[1]

    def _snapped(self, small, masks):
        """Step 7 on the working-size frames and masks (`colour_snap.snap_video`)."""
        from .colour_snap import MIN_GAIN, snap_video

        gain = MIN_GAIN if self.snap_gain is None else self.snap_gain
        masks, self.report["colour_snap"] = snap_video(small, masks, gain)
        return masks


def animal_parts(logit: np.ndarray) -> tuple[np.ndarray, int]:
    """(H, W) log-odds -> ((H, W) int32 labels 1..n of the connected parts over even odds, 0
    elsewhere; n)."""
    n, lab = cv2.connectedComponents((logit > 0).astype(np.uint8), connectivity=8)
    return lab.astype(np.int32), n - 1


def same_part(labels: np.ndarray, held: np.ndarray) -> int | None:
    """The label of the part of ``labels`` that is the animal of the (H, W) bool ``held`` mask: the
    one overlapping it most, if their intersection over union is at least ``SAME_ANIMAL_IOU``."""
    if not held.any() or not labels.any():
        return None
    hits = np.bincount(labels[held], minlength=int(labels.max()) + 1)
    hits[0] = 0
    j = int(np.argmax(hits))
    if hits[j] == 0:
        return None
    part = labels == j
    return j if hits[j] >= SAME_ANIMAL_IOU * float((part | held).sum()) else None


def network_agreement(masks, looks: dict) -> float:
    """How much (T, h, w) bool masks agree with the network's animal: over the frames of ``looks``
    (`AnimalNetSegmenter.looks`), the mean intersection over union of each mask with the cells of
    log-odds over 0 (both empty: 1)."""
    from .mask_quality import frame_j

    ious = [frame_j(masks[i], logit > 0) for i, (logit, _, _) in looks.items()]
    return float(np.mean(ious)) if ious else 0.0


def holding_part(labels: np.ndarray, held: np.ndarray) -> int | None:
    """The label of the part of ``labels`` that holds the (H, W) bool ``held`` mask: the one holding
    most of it, if that is at least ``HOLDS_TRACKED`` of it (None: no such part)."""
    held = np.asarray(held, bool)
    if not held.any() or not labels.any():
        return None
    reach = _cell_disk(labels.shape[1])
    near = cv2.dilate(labels.astype(np.float32), reach).astype(np.int32)  # of two, the larger label
    grown = np.where(labels > 0, labels, near)
    hits = np.bincount(grown[held], minlength=int(labels.max()) + 1)
    hits[0] = 0
    j = int(np.argmax(hits))
    return j if hits[j] > 0 and hits[j] >= HOLDS_TRACKED * float(held.sum()) else None


def _cell_disk(width: int) -> np.ndarray:
    """A disk one cell of the network's grid across, for a frame ``width`` pixels wide."""
    r = max(int(round(width / GRID_CELLS)), 1)
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1,) * 2)


def tracked_part(logit_of, looked: list[int], k0: int, tracked, flow):
    """The network's part of the tracked animal on frame ``k0`` and how many times the tracked area it
    covers over the ``looked`` frames -> (label or None, `part_cover` or None). The part is the one
    that is the tracked animal (`same_part`), else the one that holds the tracked mask
    (`holding_part`); it is followed along ``flow`` (`follow_part`); ``logit_of(i)``: frame i's
    (H, W) log-odds."""
    labels = animal_parts(logit_of(k0))[0]
    held = np.asarray(tracked[k0], bool)
    label = same_part(labels, held)
    label = holding_part(labels, held) if label is None else label
    if label is None:
        return None, None
    return label, part_cover(follow_part(logit_of, looked, k0, label, carry_by_flow(flow)), tracked)


def part_cover(followed, tracked) -> float | None:
    """How many times the tracked animal's area the network's part of it covers: over the (frame,
    part or None) pairs of `follow_part`, the parts' summed area over the (T, H, W) bool ``tracked``
    masks' on those frames, or None when the tracked masks do not lie in the parts (under
    ``HOLDS_TRACKED`` of their summed area) or no part was followed."""
    part_area = held_area = inside = 0
    for i, part in followed:
        if part is None:
            continue
        held = np.asarray(tracked[i], bool)
        part_area += int(part.sum())
        held_area += int(held.sum())
        inside += int((cv2.dilate(part.astype(np.uint8), _cell_disk(part.shape[1])) > 0)[held].sum())
    if part_area == 0 or held_area == 0 or inside < HOLDS_TRACKED * held_area:
        return None
    return part_area / held_area


def follow_part(logit_of, frames: list[int], start: int, label: int, carry=None):
    """Yield (frame, (H, W) bool mask or None) of one of the network's parts followed through
    ``frames`` from part ``label`` (`animal_parts`) of ``logit_of(start)``'s log-odds, outwards in
    both directions: on each frame, of the parts touching the last part found (carried there by
    ``carry(mask, from, to)``, None: left in place, and widened by half its size), the one holding the
    most probability (None: no part touches it; the last part found stays the reference)."""
    first = animal_parts(logit_of(start))[0] == label
    yield start, first
    for order in ([f for f in frames if f > start], [f for f in reversed(frames) if f < start]):
        ref, at = first, start
        for f in order:
            logit = logit_of(f)
            labels, n = animal_parts(logit)
            moved = ref if carry is None else carry(ref, at, f)
            r = max(int(0.5 * np.sqrt(ref.sum())), 1)
            disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1,) * 2)
            touching = np.unique(labels[cv2.dilate(moved.astype(np.uint8), disk) > 0])
            touching = touching[touching > 0]
            if not len(touching):
                yield f, None
                continue
            p = 1.0 / (1.0 + np.exp(-np.clip(logit, -30, 30)))
            mass = np.bincount(labels.ravel(), weights=p.ravel(), minlength=n + 1)
            ref, at = labels == int(touching[np.argmax(mass[touching])]), f
            yield f, ref


def carry_by_flow(flow):
    """``carry(mask, a, b)`` for `follow_part`: the (H, W) bool mask on frame a moved onto frame b
    by the median flow inside it, frame by frame (``flow`` a `zooctl.video.flow.VideoFlow`)."""

    def carry(mask: np.ndarray, a: int, b: int) -> np.ndarray:
        ys, xs = np.nonzero(mask)
        if not len(xs):
            return mask
        h, w = mask.shape
        dx = dy = 0.0
        step = 1 if b > a else -1
        for j in range(a, b, step):
            f = flow.forward[j] if step > 0 else flow.backward[j - 1]
            yy = np.clip(np.round(ys + dy).astype(int), 0, h - 1)
            xx = np.clip(np.round(xs + dx).astype(int), 0, w - 1)
            v = np.median(np.asarray(f)[yy, xx], axis=0)
            dx, dy = dx + float(v[0]), dy + float(v[1])
        yy, xx = np.round(ys + dy).astype(int), np.round(xs + dx).astype(int)
        keep = (yy >= 0) & (yy < h) & (xx >= 0) & (xx < w)
        out = np.zeros_like(mask)
        out[yy[keep], xx[keep]] = True
        return out

    return carry


def _kept_to(tracked, w: int, h: int, margin: float = 0.25) -> tuple[int, int, int, int] | None:
    """(x, y, w, h) around every frame's tracked mask, widened by ``margin`` of its size on each side,
    when it is at most half the frame's width and height; else None."""
    rows, cols = np.zeros(h, bool), np.zeros(w, bool)
    for m in tracked:
        m = np.asarray(m, bool)
        rows |= m.any(1)
        cols |= m.any(0)
    if not rows.any():
        return None
    y0, y1 = np.flatnonzero(rows)[[0, -1]]
    x0, x1 = np.flatnonzero(cols)[[0, -1]]
    mx, my = round(margin * (x1 - x0 + 1)), round(margin * (y1 - y0 + 1))
    x0, y0, x1, y1 = max(x0 - mx, 0), max(y0 - my, 0), min(x1 + mx + 1, w), min(y1 + my + 1, h)
    if x1 - x0 > w / 2 or y1 - y0 > h / 2:
        return None
    return int(x0), int(y0), int(x1 - x0), int(y1 - y0)


def drop_remnants(masks, remnant: float) -> list[int]:
    """Empty, in place, each (h, w) mask of ``masks`` (T, h, w) under ``remnant`` times the median
    area of the non-empty ones that does not touch the frame's edge; -> the frames emptied."""
    if remnant <= 0:
        return []
    areas = np.array([int(np.count_nonzero(m)) for m in masks])
    if not areas.any():
        return []
    small = remnant * float(np.median(areas[areas > 0]))
    dropped = []
    for i in np.flatnonzero((areas > 0) & (areas < small)):
        m = np.asarray(masks[i], bool)
        if not (m[0].any() or m[-1].any() or m[:, 0].any() or m[:, -1].any()):
            masks[i] = np.zeros_like(m)
            dropped.append(int(i))
    return dropped
