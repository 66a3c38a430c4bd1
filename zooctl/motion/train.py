"""Training loop of the motion VAE: AdamW, warm-up, gradient clipping, a loss history and its curve
as a PNG (drawn with PIL: matplotlib is not a dependency).

Schedules follow the run's *progress*, the larger of steps done / planned steps and time spent /
``max_minutes``, so a run stopped by its time budget still decays its learning rate and finishes its
KL annealing: reconstruction only for the first ``recon_warmup`` of the run (the decoder learns to
use z before the KL pulls the posterior to the prior), then the KL weight ramps up linearly over
``kl_anneal``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch

from .dataset import MotionDataset
from .losses import vae_losses
from .model import MotionVAE


@dataclass
class TrainOptions:
    epochs: int = 50
    batch_size: int = 64
    lr: float = 3e-4
    warmup_steps: int = 100
    max_minutes: float | None = None  # stop at the end of the step that passes this budget
    # Stop after this many steps (the schedule's length): a fixed amount of work whatever the load.
    max_steps: int | None = None
    recon_warmup: float = 0.1  # fraction of the run without KL
    kl_anneal: float = 0.2  # fraction of the run over which the KL weight ramps up to its value
    seed: int = 0
    device: str = "cpu"


@dataclass
class TrainHistory:
    """Per-step losses (lists of floats, one per step) and what the run did."""

    total: list[float] = field(default_factory=list)
    rotation: list[float] = field(default_factory=list)
    joints: list[float] = field(default_factory=list)
    velocity: list[float] = field(default_factory=list)
    rot_velocity: list[float] = field(default_factory=list)
    kl: list[float] = field(default_factory=list)
    active: list[float] = field(default_factory=list)
    epochs: int = 0
    steps: int = 0
    seconds: float = 0.0
    stopped_early: bool = False

    def to_json(self) -> dict:
        return {
            "epochs": self.epochs,
            "steps": self.steps,
            "seconds": round(self.seconds, 2),
            "stopped_early": self.stopped_early,
            "final": {
                k: (getattr(self, k)[-1] if getattr(self, k) else None)
                for k in ("total", "rotation", "joints", "velocity", "rot_velocity", "kl", "active")
            },
        }


def train_vae(
    model: MotionVAE,
    data: MotionDataset,
    opts: TrainOptions,
    on_step: Callable[[int, int, dict[str, float]], None] | None = None,
) -> TrainHistory:
    """Train ``model`` on ``data`` in place. ``on_step(step, total_steps, losses)`` reports progress."""
    torch.manual_seed(opts.seed)
    rng = np.random.default_rng(opts.seed)
    dev = torch.device(opts.device)
    model.to(dev).train()
    opt = torch.optim.AdamW(model.parameters(), lr=opts.lr, weight_decay=1e-4)
    steps_per_epoch = math.ceil(len(data) / opts.batch_size)  # bucketing may add a few partial batches
    total_steps = max(1, steps_per_epoch * opts.epochs)
    if opts.max_steps is not None:
        total_steps = max(1, min(total_steps, opts.max_steps))
    warm = max(1, min(opts.warmup_steps, total_steps // 10))

    budget = None if opts.max_minutes is None else 60.0 * opts.max_minutes

    def progress(step: int, elapsed: float) -> float:
        p = step / total_steps
        return min(1.0, max(p, elapsed / budget) if budget else p)

    def lr_at(step: int, p: float) -> float:  # linear warm-up, then cosine decay to 10 %
        if step < warm:
            return opts.lr * (step + 1) / warm
        return opts.lr * (0.1 + 0.9 * 0.5 * (1 + math.cos(math.pi * p)))

    def kl_scale(p: float) -> float:
        if p < opts.recon_warmup:
            return 0.0
        return min(1.0, (p - opts.recon_warmup) / opts.kl_anneal) if opts.kl_anneal > 0 else 1.0

    with torch.no_grad():
        dev6d = np.concatenate(
            [(w - np.array([1.0, 0, 0, 0, 1, 0], np.float32)).ravel() for w in data._rot6d]
        )
        model.rot_gain.fill_(float(1.0 / max(np.sqrt(np.mean(dev6d**2)), 1e-3)))
    hist = TrainHistory()
    start = time.perf_counter()
    for epoch in range(opts.epochs):
        for batch in data.batches(opts.batch_size, rng, dev):
            p = progress(hist.steps, time.perf_counter() - start)
            for g in opt.param_groups:
                g["lr"] = lr_at(hist.steps, p)
            pred, mu, logvar = model(batch.rot6d, batch.skeletons)
            losses = vae_losses(
                pred, batch.rotmat, mu, logvar, batch.skeletons, model.cfg, kl_scale(p), batch.joint_motion
            )
            opt.zero_grad(set_to_none=True)
            losses["total"].backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
            opt.step()
            vals = {k: float(v.detach()) for k, v in losses.items()}
            if not math.isfinite(vals["total"]):
                from ..errors import ZooctlError

                raise ZooctlError(
                    "training diverged (loss is not finite)", hint="lower --lr or use a smaller model"
                )
            for k, v in vals.items():
                getattr(hist, k).append(v)
            hist.steps += 1
            if on_step is not None:
                on_step(hist.steps, total_steps, vals)
            over_steps = opts.max_steps is not None and hist.steps >= total_steps
            if over_steps or (budget is not None and time.perf_counter() - start > budget):
                hist.stopped_early = True
                break
        hist.epochs = epoch + 1
        if hist.stopped_early:
            break
    hist.seconds = time.perf_counter() - start
    model.eval()
    return hist


def loss_curve_png(hist: TrainHistory, size: tuple[int, int] = (640, 360)) -> bytes:
    """A log-scale plot of the per-step losses (total, rotation, joints), smoothed, as PNG bytes."""
    import io

    from PIL import Image, ImageDraw

    W, H = size
    left, right, top, bottom = 58, 12, 26, 32
    img = Image.new("RGB", (W, H), (255, 255, 255))
    d = ImageDraw.Draw(img)
    series = [("total", (20, 20, 20)), ("rotation", (200, 60, 40)), ("joints", (40, 110, 200))]
    curves = {}
    for name, _ in series:
        v = np.asarray(getattr(hist, name), dtype=np.float64)
        v = v[np.isfinite(v) & (v > 0)]
        if len(v):
            k = max(1, len(v) // 50)  # moving average over ~2 % of the run
            curves[name] = np.convolve(v, np.ones(k) / k, mode="valid") if len(v) >= k else v
    d.rectangle([left, top, W - right, H - bottom], outline=(120, 120, 120))
    d.text((left, 6), f"motion prior training loss ({hist.steps} steps, log scale)", fill=(0, 0, 0))
    if curves:
        lo = math.log10(min(c.min() for c in curves.values()))
        hi = math.log10(max(c.max() for c in curves.values()))
        lo, hi = math.floor(lo), max(math.ceil(hi), math.floor(lo) + 1)
        pw, ph = W - left - right, H - top - bottom
        for e in range(lo, hi + 1):  # decade grid lines
            y = top + ph * (1 - (e - lo) / (hi - lo))
            d.line([left, y, W - right, y], fill=(225, 225, 225))
            d.text((6, y - 6), f"1e{e}", fill=(80, 80, 80))
        n = max(len(c) for c in curves.values())
        for i, (name, color) in enumerate(series):
            c = curves.get(name)
            if c is None:
                continue
            xs = left + pw * np.arange(len(c)) / max(1, n - 1)
            ys = top + ph * (1 - (np.log10(c) - lo) / (hi - lo))
            d.line(list(zip(xs.tolist(), ys.tolist(), strict=True)), fill=color, width=2)
            d.text((left + 8 + 90 * i, H - bottom + 8), name, fill=color)
        d.text((W - right - 60, H - bottom + 8), f"step {hist.steps}", fill=(80, 80, 80))
    buf = io.BytesIO()
    img.save(buf, format="PNG")
    return buf.getvalue()
