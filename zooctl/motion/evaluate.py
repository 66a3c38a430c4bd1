"""Held-out evaluation of a motion prior against the baselines (what `zooctl bench motion` and
``bench/motion.py`` report).

Per skeleton with held-out clips: real = held-out windows; each method generates the same number
of windows (at least ``samples``) of the prior's length; metrics from `metrics` are averaged over
skeletons. The VAE's reconstruction error is measured on the held-out windows.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from . import metrics as M
from .baselines import PCABaseline, RetrievalBaseline
from .dataset import MotionSequence, holdout_split, resample, sequences_from_asset, windows

METHODS = ("ponymation", "pca", "retrieval", "real")


def split_assets(
    assets: Sequence[Any], fraction: float = 0.2, seed: int = 0, holdout: dict[str, list[str]] | None = None
) -> tuple[list[MotionSequence], list[MotionSequence], dict[str, list[str]]]:
    """Train and held-out sequences of assets' clips; ``holdout`` (asset -> clips) overrides the
    hashed split of ``fraction`` (`dataset.holdout_split`)."""
    if holdout is None:
        holdout = holdout_split({a.name: list(a.clips) for a in assets}, fraction, seed)
    train, test = [], []
    for a in assets:
        held = set(holdout.get(a.name, []))
        for s in sequences_from_asset(a):
            (test if s.name.split("/", 1)[1] in held else train).append(s)
    return train, test, holdout


def _windows(seqs: Sequence[MotionSequence], length: int, fps: float) -> dict[str, tuple[Any, np.ndarray]]:
    out: dict[str, tuple[Any, list[np.ndarray]]] = {}
    for s in seqs:
        w = windows(resample(s, fps), length, max(1, length // 2))
        if len(w):
            out.setdefault(s.skeleton.key, (s.skeleton, []))[1].append(w)
    return {k: (sk, np.concatenate(ws)) for k, (sk, ws) in out.items()}


def evaluate(
    prior: Any,
    train: Sequence[MotionSequence],
    test: Sequence[MotionSequence],
    samples: int = 32,
    seed: int = 0,
    temperature: float | None = None,
) -> dict[str, Any]:
    """Metrics of ``prior`` (a `PonymationPrior`, sampled at ``temperature``, default its calibrated one) and of both baselines
    on the held-out windows."""
    L, fps = prior.cfg.length, prior.cfg.fps
    train_w, test_w = _windows(train, L, fps), _windows(test, L, fps)
    retrieval, pca = RetrievalBaseline(), PCABaseline()
    for sk, w in train_w.values():
        retrieval.add(sk, w)
        pca.add(sk, w)
    per: dict[str, dict[str, dict[str, float | None]]] = {}
    for key, (sk, real) in sorted(test_w.items()):
        if key not in train_w:
            continue  # baselines need training windows of the same skeleton
        n = max(samples, len(real))
        gen = {
            "ponymation": prior.sample_delta(sk, n, L, seed=seed, temperature=temperature),
            "pca": pca.sample(sk, n, seed=seed),
            "retrieval": retrieval.sample(sk, n, seed=seed),
            "real": real,
        }
        p_real = M.joint_positions(real, sk)
        feet = sk.feet()
        row: dict[str, dict[str, float | None]] = {}
        for name, w in gen.items():
            p = M.joint_positions(w, sk)
            row[name] = {
                "mcd": None if name == "real" else M.motion_chamfer(p, p_real),
                "diversity": M.diversity(p),
                "smoothness": M.smoothness(p),
                "foot_sliding": M.foot_sliding(p, feet),
            }
        rec = prior.reconstruct(real, sk)
        row["ponymation"]["recon_mpjpe"] = M.mpjpe(M.joint_positions(rec, sk), p_real)
        row["ponymation"]["recon_rot_deg"] = M.rotation_error_deg(rec, real)
        per[key] = row
    table = {m: _mean([per[k][m] for k in per]) for m in METHODS}
    return {
        "skeletons": sorted(per),
        "held_out_windows": int(sum(len(test_w[k][1]) for k in per)),
        "samples_per_skeleton": samples,
        "units": "joint positions in % of the skeleton's rest diagonal, body frame (no root motion); "
        "mcd in %^2, smoothness in % per frame^2, foot sliding in % per frame",
        "table": table,
        "per_skeleton": per,
    }


def _mean(rows: list[dict[str, float | None]]) -> dict[str, float | None]:
    keys = {k for r in rows for k in r}
    out: dict[str, float | None] = {}
    for k in sorted(keys):
        v = [r[k] for r in rows if r.get(k) is not None]
        out[k] = float(np.mean(v)) if v else None
    return out


def format_table(result: dict[str, Any]) -> list[list[str]]:
    """Rows for `zooctl.cli._common.print_table` (columns: method and each metric)."""
    rows = []
    for m in METHODS:
        r = result["table"].get(m, {})
        cells = [m]
        for k in ("recon_mpjpe", "mcd", "diversity", "smoothness", "foot_sliding"):
            v = r.get(k)
            cells.append("-" if v is None else f"{v:.3f}")
        rows.append(cells)
    return rows


TABLE_COLUMNS = [
    ("method", "left"),
    ("recon MPJPE %", "right"),
    ("MCD %^2", "right"),
    ("diversity %", "right"),
    ("accel %", "right"),
    ("foot slide %", "right"),
]
