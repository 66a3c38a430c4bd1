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
else ``ZOOCTL_ANIMALNET_WEIGHTS``, else ``STORE/models/animalnet.npz``.
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


def default_weights() -> Path:
    """Where `zooctl segment train` writes the weights by default: STORE/models/animalnet.npz."""
    from ..paths import default_store

    return default_store() / "models" / "animalnet.npz"


def weights_file(weights: str | Path | None = None) -> Path:
    """The weights to load: the argument, ZOOCTL_ANIMALNET_WEIGHTS, else `default_weights`."""
    p = Path(weights or os.environ.get("ZOOCTL_ANIMALNET_WEIGHTS") or default_weights()).expanduser()
    if not p.is_file():
        raise InputError(
            f"animalnet weights {p} do not exist",
            hint="train them with `zooctl segment train` or point ZOOCTL_ANIMALNET_WEIGHTS at a weights .npz",
        )
    return p


def motion_grid(flow: np.ndarray | None, grid: tuple[int, int]) -> np.ndarray:
    """(H, W, 2) flow of a frame (or None: no motion known) -> (gh, gw) float32 in [0, 1): the
    motion the camera does not explain, in hundredths of the frame's width, squashed by tanh(x/2)."""
    gh, gw = grid
    if flow is None:
        return np.zeros(grid, np.float32)
    from .cues import background_motion_residual

    r = background_motion_residual(np.ascontiguousarray(flow, np.float32)) * (100.0 / flow.shape[1])
    return np.tanh(cv2.resize(r, (gw, gh), interpolation=cv2.INTER_AREA) / 2.0).astype(np.float32)


def frame_inputs(net, frame: np.ndarray, flow: np.ndarray | None) -> np.ndarray:
    """(gh, gw, IN_CHANNELS) float32 input of one (H, W, 3) uint8 RGB frame; ``net`` a
    `zooctl.video.selftrain.FeatureNet` at ``FEATURE_WIDTH``; ``flow`` its flow to a neighbour."""
    feats, cam = net.features(frame)
    motion = motion_grid(flow, cam.shape)
    return np.concatenate([feats, cam[..., None], motion[..., None]], -1)


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
    masks decided again with the network's evidence.

    Every ``feature_every``-th frame (and the last) the network gives each cell's log-odds that an
    animal is there (the frames between: their neighbours' carried along the flow, as `selftrain`
    does); per pixel at the tracker's working size, the animal's log-odds are ``net_weight`` x the
    network's where it sees an animal (and where it sees none too, with ``erase``) plus
    ``prior_weight`` inside the tracked mask (minus it outside), and the connected part over even odds
    that holds the most probability is the animal. Without ``erase`` the network can add what the
    tracker lost but not remove what it holds (a large animal unlike any it was trained on). ``weights``: the head's ``.npz``
    (`weights_file`). Other options go to the tracker (`zooctl.video.grabcut.GrabCutTracker`).
    ``report``: the tracker's, with ``animalnet`` added (weights, share of mask pixels changed).
    """

    name = "animalnet"
    uses_flow = True

    def __init__(
        self,
        weights: str | Path | None = None,
        feature_every: int = 1,
        net_weight: float = 1.0,
        prior_weight: float = 2.0,
        erase: bool = False,
        **tracker_options,
    ) -> None:
        from ..errors import UsageError
        from .grabcut import GrabCutTracker

        if feature_every < 1:
            raise UsageError(f"feature_every must be at least 1, got {feature_every}")
        self.net = AnimalNet(weights)  # before the slow part: missing weights are refused at once
        self.tracker = GrabCutTracker(**tracker_options)
        self.feature_every = feature_every
        self.net_weight = net_weight
        self.prior_weight = prior_weight
        self.erase = erase
        self._features = None
        self.report: dict = {}

    def flow_size(self, w: int, h: int) -> tuple[int, int]:
        """(w, h) the tracker (and this segmenter) works at: the flow it reads, at that size."""
        return self.tracker.flow_size(w, h)

    def evidence(self, frames, flow, progress=None) -> np.ndarray:
        """(T, h, w) float32 network log-odds at the flow's size for (T, H, W, 3) frames; ``flow``
        a `zooctl.video.flow.VideoFlow` at the working size."""
        from .scratch import working
        from .selftrain import FeatureNet, carry_between, grid_to_pixels

        t = len(frames)
        h, w = flow.forward.shape[1:3]
        if self._features is None:
            self._features = FeatureNet(int(self.net.info.get("feature_width", FEATURE_WIDTH)))
        looked = sorted(set(range(0, t, self.feature_every)) | {t - 1})
        out = working(frames, t, (h, w), np.float32)
        for k, i in enumerate(looked):
            frame = frames[i]
            if frame.shape[:2] != (h, w):
                frame = cv2.resize(frame, (w, h), interpolation=cv2.INTER_AREA)
            motion = flow.forward[i] if i < t - 1 else -np.asarray(flow.backward[i - 1])
            grid = self.net.logits(frame_inputs(self._features, frame, motion))
            out[i] = grid_to_pixels(grid, w, h, self._features.input_size(w, h))
            if progress:
                progress(k + 1, len(looked))
        carry_between(out, looked, flow)
        return out

    def decide(self, evidence: np.ndarray, tracked: np.ndarray) -> np.ndarray:
        """(h, w) network log-odds and (h, w) bool tracked mask -> (h, w) bool mask."""
        from .selftrain import main_animal

        prior = np.where(tracked, self.prior_weight, -self.prior_weight)
        net = evidence if self.erase else np.maximum(evidence, 0.0)
        return main_animal(self.net_weight * net + prior)

    def segment(self, frames, box=None, progress=None, flow=None, box_frame: int = 0) -> np.ndarray:
        """(T, H, W, 3) uint8 RGB frames, optional box on frame ``box_frame`` -> (T, H, W) bool masks."""
        from .scratch import working
        from .selftrain import at_frame_size, track

        t = len(frames)
        flow, tracked = track(self.tracker, frames, box, progress, flow, box_frame, "animalnet")
        sh, sw = flow.forward.shape[1:3]
        self.report = dict(self.tracker.report)
        evidence = self.evidence(
            frames, flow, (lambda d, n: progress(t + d * t // n, 2 * t)) if progress else None
        )
        out = working(frames, t, (sh, sw), bool)
        changed = total = 0
        for i in range(t):
            m = np.asarray(tracked[i], bool)
            if m.shape != (sh, sw):
                m = cv2.resize(m.astype(np.float32), (sw, sh), interpolation=cv2.INTER_AREA) > 0.5
            out[i] = self.decide(evidence[i], m)
            changed += int((out[i] != m).sum())
            total += int(m.sum())
        self.report["animalnet"] = {
            "weights": str(self.net.path),
            "changed": round(changed / max(total, 1), 4),
        }
        return at_frame_size(out, frames)
