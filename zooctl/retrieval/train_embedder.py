"""Train the ``procnet`` retrieval head on procedural animals (`zooctl embed train`).

The backbone stays frozen (EfficientNet-Lite0 features and the silhouette descriptor, see
`zooctl.retrieval.train_data`); a two-layer MLP maps their concatenation to a unit-length
embedding, trained with a supervised contrastive loss (Khosla et al. 2020) whose positives are
views of the same body plan, plus the same loss over animal identity (views of one animal) with
weight ``identity_weight``. Batches hold ``animals_per_batch`` animals x ``views_per_animal``
views, balanced over body plans. Deterministic for a seed on the CPU. The result is written as a
numpy ``.npz`` (`zooctl.embed.procnet`), with the loss curve as a PNG beside it.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from .train_data import FEATURES, TrainingSet


@dataclass
class TrainConfig:
    """Head size (MLP hidden width, embedding dim), optimiser, loss and batch composition."""

    hidden: int = 512
    dim: int = 128
    # AdamW with a cosine schedule over `steps`; `minutes` caps the wall time
    steps: int = 1500
    lr: float = 1e-3
    weight_decay: float = 1e-4
    minutes: float | None = None
    # SupCon over body plan, plus identity_weight x SupCon over animal identity
    temperature: float = 0.1
    identity_weight: float = 0.5
    inputs: tuple[str, ...] = FEATURES  # frozen features the head reads, concatenated
    # a batch: animals_per_batch animals x views_per_animal views; dropout on the frozen features
    animals_per_batch: int = 32
    views_per_animal: int = 4
    input_dropout: float = 0.2
    seed: int = 0
    # with a bank set (`embed train --bank`): this share of each batch's animals are bank assets
    bank_fraction: float = 0.25


def supcon(z, labels, temperature: float):
    """Supervised contrastive loss of unit rows z (B, D) with integer labels (B,); rows labelled
    -1 (unknown) are neither anchors nor positives, but stay negatives of the others."""
    import torch

    sim = z @ z.T / temperature
    eye = torch.eye(len(z), dtype=torch.bool, device=z.device)
    sim = sim.masked_fill(eye, -1e9)
    logp = sim - torch.logsumexp(sim, dim=1, keepdim=True)
    pos = (labels[:, None] == labels[None, :]) & ~eye & (labels >= 0)[:, None]
    n = pos.sum(1)
    keep = n > 0
    if not bool(keep.any()):  # no row has a positive: nothing to pull together
        return z.sum() * 0.0
    return -((logp * pos).sum(1)[keep] / n[keep]).mean()


def make_head(in_dim: int, cfg: TrainConfig):
    import torch

    return torch.nn.Sequential(
        torch.nn.Dropout(cfg.input_dropout),
        torch.nn.Linear(in_dim, cfg.hidden),
        torch.nn.ReLU(),
        torch.nn.Linear(cfg.hidden, cfg.dim),
    )


def _batch(
    rng: np.random.Generator,
    views: dict,
    by_label: list[np.ndarray],
    cfg: TrainConfig,
    bank: np.ndarray | None = None,
):
    """Row indices of one batch: animals drawn plan-balanced (``bank``: a ``cfg.bank_fraction``
    share of them drawn from these bank animals instead), views drawn within each animal."""
    rows = []
    n_bank = 0 if bank is None or not len(bank) else int(round(cfg.bank_fraction * cfg.animals_per_batch))
    for k in range(cfg.animals_per_batch):
        animals = by_label[(k + int(rng.integers(len(by_label)))) % len(by_label)] if k >= n_bank else bank
        v = views[int(animals[int(rng.integers(len(animals)))])]
        rows.append(rng.choice(v, size=min(cfg.views_per_animal, len(v)), replace=False))
    return np.concatenate(rows)


def merge_sets(ts: TrainingSet, bank: TrainingSet) -> tuple[TrainingSet, np.ndarray]:
    """``ts`` with ``bank``'s rows appended (its animals renumbered after ``ts``'s, its labels mapped
    by name onto ``ts.labels``, -1 where unknown); returns it and the bank's animal ids."""
    off = int(ts.animal.max()) + 1 if len(ts) else 0
    lab = np.array(
        [
            ts.labels.index(bank.labels[k]) if k >= 0 and bank.labels[k] in ts.labels else -1
            for k in bank.label
        ]
    )
    merged = TrainingSet(
        {f: np.concatenate([ts.features[f], bank.features[f]]) for f in ts.features},
        np.concatenate([ts.label, lab.astype(np.int64)]),
        np.concatenate([ts.animal, bank.animal + off]),
        ts.labels,
    )
    return merged, np.unique(bank.animal) + off


def train_head(
    ts: TrainingSet,
    cfg: TrainConfig,
    device: str = "cpu",
    progress: Callable[[int, int, float], None] | None = None,
    bank: TrainingSet | None = None,
    init: dict[str, np.ndarray] | None = None,
) -> tuple[dict[str, np.ndarray], list[float]]:
    """Train on ``ts``; returns the head's numpy weights (`zooctl.embed.procnet` layout) and the
    loss per step. Stops after ``cfg.steps`` steps or ``cfg.minutes``, whichever comes first.
    ``bank``: the user's bank views (`zooctl.retrieval.train_bank`), mixed into every batch
    (``cfg.bank_fraction``); ``init``: weights to start from (fine-tuning) instead of random ones."""
    import torch

    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    bank_animals = None
    if bank is not None and len(bank):
        ts, bank_animals = merge_sets(ts, bank)
    x_all = torch.from_numpy(np.concatenate([ts.features[f] for f in cfg.inputs], 1).astype(np.float32))
    lab = torch.from_numpy(ts.label)
    ani = torch.from_numpy(ts.animal)
    dev = torch.device(device)
    head = make_head(x_all.shape[1], cfg).to(dev)
    if init is not None:
        lin = [m for m in head if isinstance(m, torch.nn.Linear)]
        with torch.no_grad():
            for m, w, b in ((lin[0], init["w1"], init["b1"]), (lin[1], init["w2"], init["b2"])):
                m.weight.copy_(torch.from_numpy(np.asarray(w, np.float32).T))
                m.bias.copy_(torch.from_numpy(np.asarray(b, np.float32)))
    opt = torch.optim.AdamW(head.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, cfg.steps)
    proc = ts.animal if bank_animals is None else np.where(np.isin(ts.animal, bank_animals), -1, ts.animal)
    by_label = [np.unique(proc[(ts.label == k) & (proc >= 0)]) for k in range(len(ts.labels))]
    by_label = [a for a in by_label if len(a)]
    views = {int(a): np.flatnonzero(ts.animal == a) for a in np.unique(ts.animal)}
    losses = []
    t0 = time.perf_counter()
    head.train()
    for step in range(cfg.steps):
        idx = torch.from_numpy(_batch(rng, views, by_label, cfg, bank_animals))
        z = torch.nn.functional.normalize(head(x_all[idx].to(dev)), dim=1)
        loss = supcon(z, lab[idx].to(dev), cfg.temperature)
        if cfg.identity_weight > 0:
            loss = loss + cfg.identity_weight * supcon(z, ani[idx].to(dev), cfg.temperature)
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        losses.append(float(loss.detach()))
        if progress is not None:
            progress(step + 1, cfg.steps, losses[-1])
        if cfg.minutes is not None and time.perf_counter() - t0 > 60 * cfg.minutes:
            break
    lin = [m for m in head if isinstance(m, torch.nn.Linear)]
    weights = {
        "w1": lin[0].weight.detach().cpu().numpy().T.astype(np.float32),
        "b1": lin[0].bias.detach().cpu().numpy().astype(np.float32),
        "w2": lin[1].weight.detach().cpu().numpy().T.astype(np.float32),
        "b2": lin[1].bias.detach().cpu().numpy().astype(np.float32),
    }
    return weights, losses


def save_model(
    path: Path, weights: dict[str, np.ndarray], cfg: TrainConfig, ts: TrainingSet, meta: dict
) -> Path:
    """Write the weights ``.npz`` atomically (float16 matrices: half the size, same retrieval)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    info = {"inputs": list(cfg.inputs), "labels": ts.labels, "config": asdict(cfg), **meta}
    tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}.npz")
    np.savez(
        tmp,
        w1=weights["w1"].astype(np.float16),
        b1=weights["b1"],
        w2=weights["w2"].astype(np.float16),
        b2=weights["b2"],
        info=np.array(json.dumps(info, sort_keys=True)),
    )
    os.replace(tmp, path)
    return path


def plot_losses(losses: list[float], path: Path, title: str) -> Path:
    """The loss curve (per step, grey; 50-step running mean, blue) as a PNG, drawn with OpenCV."""
    import cv2

    W, H, m = 640, 360, 40
    img = np.full((H, W, 3), 255, np.uint8)
    y = np.asarray(losses, np.float64)
    lo, hi = float(y.min()), float(y.max()) + 1e-9

    def pts(v: np.ndarray, x0: int = 0) -> np.ndarray:
        xs = m + (np.arange(len(v)) + x0) / max(len(y) - 1, 1) * (W - 2 * m)
        ys = H - m - (v - lo) / (hi - lo) * (H - 2 * m)
        return np.stack([xs, ys], 1).round().astype(np.int32)

    cv2.rectangle(img, (m, m), (W - m, H - m), (0, 0, 0), 1)
    cv2.polylines(img, [pts(y)], False, (190, 190, 190), 1, cv2.LINE_AA)
    if len(y) >= 50:
        cv2.polylines(img, [pts(np.convolve(y, np.ones(50) / 50, "valid"), 49)], False, (200, 80, 0), 2)
    font = cv2.FONT_HERSHEY_SIMPLEX
    cv2.putText(img, title, (m, 25), font, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(img, f"{hi:.2f}", (2, m + 5), font, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(img, f"{lo:.2f}", (2, H - m), font, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(img, f"step {len(y)}", (W - m - 70, H - 12), font, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(
        img,
        "loss: SupCon plan + identity (grey: step, blue: 50-step mean)",
        (m, H - 12),
        font,
        0.4,
        (0, 0, 0),
        1,
        cv2.LINE_AA,
    )
    tmp = Path(path).with_name(f".{Path(path).stem}.tmp{os.getpid()}.png")
    cv2.imwrite(str(tmp), img)
    os.replace(tmp, path)
    return Path(path)
