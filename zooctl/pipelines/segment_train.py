"""`zooctl segment train`: the ``animalnet`` head learned from synthetic composites.

1. ``samples`` composites (`zooctl.benchdata.composites`) of the given assets (the bank's and
   procedural ones) over procedural scenes, each turned into the network's input
   (`zooctl.video.animalnet.frame_inputs`: frozen EfficientNet-Lite0 features, the class map, the
   motion residual of DIS flow between its two frames) and its mask's share of every grid cell;
2. the head (`zooctl.video.animalnet.HEAD`) trained on them with Adam (binary cross-entropy
   against the cells' shares plus a soft Dice term, so small animals count), a tenth held out to
   report its IoU;
3. the weights written atomically as ``.npz`` with what they were made from.

Torch is used for training only; the segmenter applies the head in numpy.
"""

from __future__ import annotations

import io
import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..asset import RiggedAsset
from ..errors import UsageError

Progress = Callable[[str, int, int], None]


@dataclass
class SegmentTrainConfig:
    samples: int = 2000
    steps: int = 1500
    batch: int = 16
    lr: float = 2e-3
    weight_decay: float = 1e-4
    dice: float = 0.5
    seed: int = 0
    size: tuple[int, int] = (448, 336)
    components: int = 127
    crop: tuple[int, int] = (24, 32)


def make_inputs(
    assets: list[RiggedAsset], cfg: SegmentTrainConfig, progress: Progress | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(N, gh, gw, C) float16 inputs and (N, gh, gw) float32 animal share per cell of ``cfg.samples``
    composites of ``assets``."""
    import cv2

    from ..benchdata.composites import composite
    from ..video.animalnet import FEATURE_WIDTH, frame_inputs
    from ..video.flow import DISFlow
    from ..video.selftrain import FeatureNet

    rng = np.random.default_rng(cfg.seed)
    net = FeatureNet(FEATURE_WIDTH)
    dis = DISFlow("medium")
    iw, ih = net.input_size(*cfg.size)
    gh, gw = ih // 8, iw // 8
    x = np.zeros((cfg.samples, gh, gw, 0), np.float16)
    y = np.zeros((cfg.samples, gh, gw), np.float32)
    for i in range(cfg.samples):
        s = composite(assets, rng, cfg.size)
        inp = frame_inputs(net, s.frames[0], dis.flow(s.frames[0], s.frames[1]))
        if x.shape[-1] == 0:
            x = np.zeros((cfg.samples, gh, gw, inp.shape[-1]), np.float16)
        x[i] = inp
        # the grid cell j is centred on input pixel 8 j: area shares over the cell's footprint
        y[i] = cv2.resize(
            cv2.resize(s.mask.astype(np.float32), (iw, ih), interpolation=cv2.INTER_AREA),
            (gw, gh),
            interpolation=cv2.INTER_AREA,
        )
        if progress:
            progress("composites", i + 1, cfg.samples)
    return x, y


def input_projection(x: np.ndarray, components: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Standardisation and principal axes of the appearance channels (all but the last, motion) of
    a sample ``x`` (N, gh, gw, C) -> (mean (C-1,), std (C-1,), proj (C-1, components)) float32."""
    a = x[..., :-1].reshape(-1, x.shape[-1] - 1).astype(np.float32)
    mean, std = a.mean(0), a.std(0) + 1e-3
    z = (a - mean) / std
    _, _, vt = np.linalg.svd(z[:: max(len(z) // 50000, 1)], full_matrices=False)
    proj = vt[: min(components, len(vt))].T
    return mean.astype(np.float32), std.astype(np.float32), np.ascontiguousarray(proj, np.float32)


def project_inputs(
    x: np.ndarray, mean: np.ndarray, std: np.ndarray, proj: np.ndarray, chunk: int = 64
) -> np.ndarray:
    """(N, gh, gw, C) inputs -> (N, P + 1, gh, gw) float32: the projected appearance channels and
    the motion channel as it is (0 means no motion)."""
    n, gh, gw, _ = x.shape
    out = np.empty((n, proj.shape[1] + 1, gh, gw), np.float32)
    for k in range(0, n, chunk):
        b = x[k : k + chunk].astype(np.float32)
        a = ((b[..., :-1] - mean) / std) @ proj
        out[k : k + chunk] = np.concatenate([a, b[..., -1:]], -1).transpose(0, 3, 1, 2)
    return out


def _model(channels: int):
    import torch.nn as nn

    from ..video.animalnet import HEAD

    layers, cin = [], channels
    for k, (name, kernel, dilation, cout) in enumerate(HEAD):
        conv = nn.Conv2d(cin, cout, kernel, padding=dilation * (kernel // 2), dilation=dilation)
        layers.append((name, conv))
        if k < len(HEAD) - 1:
            layers.append((f"{name}_relu", nn.ReLU()))
        cin = cout
    from collections import OrderedDict

    return nn.Sequential(OrderedDict(layers))


def train_head(
    x: np.ndarray,
    y: np.ndarray,
    cfg: SegmentTrainConfig,
    progress: Progress | None = None,
    device: str = "cpu",
) -> tuple[dict[str, np.ndarray], dict]:
    """Train the head on inputs ``x`` (N, gh, gw, C) and shares ``y`` (N, gh, gw) -> (parameters by
    name, with the standardisation ``mean``/``std``; report: losses, held-out IoU)."""
    import torch
    import torch.nn.functional as F

    if len(x) < 10:
        raise UsageError(f"too few training samples ({len(x)}): ask for at least 10")
    g = torch.Generator().manual_seed(cfg.seed)
    torch.manual_seed(cfg.seed)
    n = len(x)
    order = torch.randperm(n, generator=g).numpy()
    held, used = order[: max(n // 10, 1)], order[max(n // 10, 1) :]
    mean, std, proj = input_projection(x[used[: min(len(used), 400)]], cfg.components)
    if progress:
        progress("training", 0, cfg.steps)
    dev = torch.device(device)
    xt = torch.as_tensor(project_inputs(x, mean, std, proj)).to(dev)  # (N, P, gh, gw)
    yt = torch.as_tensor(y).to(dev)
    model = _model(xt.shape[1]).to(dev)
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=cfg.lr, total_steps=cfg.steps, pct_start=0.1)
    gh, gw = y.shape[1:]
    ch, cw = min(gh, cfg.crop[0]), min(gw, cfg.crop[1])

    losses = []
    for step in range(cfg.steps):
        idx = torch.as_tensor(used[torch.randint(len(used), (cfg.batch,), generator=g).numpy()], device=dev)
        # a random window of the grid each step: the head is convolutional, the cost is in the cells
        oy = int(torch.randint(gh - ch + 1, (1,), generator=g))
        ox = int(torch.randint(gw - cw + 1, (1,), generator=g))
        xb, yb = xt[idx][..., oy : oy + ch, ox : ox + cw], yt[idx][:, oy : oy + ch, ox : ox + cw]
        if step % 2:  # left-right flips: an animal facing the other way is still one
            xb, yb = xb.flip(-1), yb.flip(-1)
        logit = model(xb)[:, 0]
        bce = F.binary_cross_entropy_with_logits(logit, yb)
        p = torch.sigmoid(logit)
        inter = (p * yb).sum((1, 2))
        dice = 1 - (2 * inter + 1) / (p.sum((1, 2)) + yb.sum((1, 2)) + 1)
        loss = bce + cfg.dice * dice.mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        losses.append(loss.item())
        if progress:
            progress("training", step + 1, cfg.steps)
    model.eval()
    with torch.no_grad():
        ious = []
        for k in range(0, len(held), 64):
            idx = torch.as_tensor(held[k : k + 64], device=dev)
            p = model(xt[idx])[:, 0] > 0
            t = yt[idx] > 0.5
            ious += ((p & t).sum((1, 2)) / (p | t).sum((1, 2)).clamp(min=1)).tolist()
    params = {k: v.detach().cpu().numpy().astype(np.float32) for k, v in model.state_dict().items()}
    params["mean"], params["std"], params["proj"] = mean, std, proj
    span = max(1, min(50, len(losses) // 4))
    report = {
        "loss_first": float(np.mean(losses[:span])),
        "loss_last": float(np.mean(losses[-span:])),
        "held_out_cell_iou": float(np.mean(ious)),
        "held_out": int(len(held)),
    }
    return params, report


def save_weights(path: Path, params: dict[str, np.ndarray], info: dict) -> Path:
    """Write the head's weights and ``info`` atomically as an ``.npz``."""
    from ..store.fs import write_bytes_atomic

    buf = io.BytesIO()
    np.savez(buf, info=np.array(json.dumps(info)), **params)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_bytes_atomic(path, buf.getvalue())
    return path


def train(
    assets: list[RiggedAsset],
    out: Path,
    cfg: SegmentTrainConfig,
    sources: dict,
    progress: Progress | None = None,
    device: str = "cpu",
) -> dict:
    """The whole job (module docstring): -> report (written into the weights' ``info`` too).
    ``sources``: what the assets are and their licence, recorded with the weights."""
    from ..video.animalnet import FEATURE_WIDTH

    if not assets:
        raise UsageError("no assets to train on", hint="add animals to the bank or ask for procedural ones")
    t0 = time.perf_counter()
    x, y = make_inputs(assets, cfg, progress)
    t1 = time.perf_counter()
    params, report = train_head(x, y, cfg, progress, device)
    t2 = time.perf_counter()
    info = {
        "feature_width": FEATURE_WIDTH,
        "config": {**asdict(cfg), "size": list(cfg.size)},
        "assets": len(assets),
        "sources": sources,
        "report": report,
        "seconds": {"composites": round(t1 - t0, 1), "training": round(t2 - t1, 1)},
    }
    save_weights(out, params, info)
    return info
