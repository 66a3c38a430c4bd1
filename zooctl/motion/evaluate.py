"""Held-out evaluation of a motion prior against the baselines (what `zooctl bench motion` and
``bench/motion.py`` report).

Per skeleton with held-out clips: real = held-out windows; each method generates the same number
of windows (at least ``samples``) of the prior's length; metrics from `metrics` are averaged over
skeletons. The VAE's reconstruction error is measured on the held-out windows.

A statue can score a fair MCD, so motion itself is measured on *long* windows (``long_frames``,
the prior's samples chained from several segments) against held-out windows of that length: the
per-joint amplitude and speed ratios (samples / held-out data, 1 moves like the data), gait
periodicity (legged skeletons), and for the prior the velocity jump at its seams against the
data's 95th percentile of frame-to-frame velocity change.
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


def _baselines(train_w: dict[str, tuple[Any, np.ndarray]]) -> tuple[PCABaseline, RetrievalBaseline]:
    pca, retrieval = PCABaseline(), RetrievalBaseline()
    for sk, w in train_w.values():
        retrieval.add(sk, w)
        pca.add(sk, w)
    return pca, retrieval


def evaluate(
    prior: Any,
    train: Sequence[MotionSequence],
    test: Sequence[MotionSequence],
    samples: int = 32,
    seed: int = 0,
    temperature: float | None = None,
    long_frames: int = 30,
    seeds: int = 1,
) -> dict[str, Any]:
    """Metrics of ``prior`` (a `PonymationPrior`, sampled at ``temperature``, default its
    `sample_temperature`) and of both baselines on the held-out windows.

    With ``seeds`` > 1 every method samples with seeds ``seed`` .. ``seed + seeds - 1``; ``table``
    is the mean over them, ``table_sd`` their standard deviation and ``per_seed`` each one's table:
    with 32 windows per skeleton one seed's diversity moves by about 0.5, as much as the gap
    between two methods (BENCHMARKS.md). ``per_skeleton`` is the first seed's.
    """
    L, fps = prior.cfg.length, prior.cfg.fps
    short, long = _Split(train, test, L, fps), _Split(train, test, max(long_frames, L), fps)
    recon: dict[str, dict[str, float | None]] = {}  # does not depend on the seed: computed once
    runs = [
        _evaluate_seed(prior, short, long, samples, seed + i, temperature, recon)
        for i in range(max(1, seeds))
    ]
    out = runs[0]
    if len(runs) > 1:
        tables = [r["table"] for r in runs]
        mean: dict[str, dict[str, float | None]] = {}
        sd: dict[str, dict[str, float | None]] = {}
        for m in out["table"]:
            mean[m], sd[m] = {}, {}
            for k in out["table"][m]:
                v = [t[m][k] for t in tables if t.get(m, {}).get(k) is not None]
                mean[m][k] = float(np.mean(v)) if v else None
                sd[m][k] = float(np.std(v)) if v else None
        out = {**out, "table": mean, "table_sd": sd, "per_seed": tables}
    out["seeds"] = [seed + i for i in range(len(runs))]
    return out


class _Split:
    """Training and held-out windows of one length per skeleton key, and the baselines fitted to
    the training ones."""

    def __init__(
        self, train: Sequence[MotionSequence], test: Sequence[MotionSequence], length: int, fps: float
    ):
        self.length = length
        self.train, self.test = _windows(train, length, fps), _windows(test, length, fps)
        self.pca, self.retrieval = _baselines(self.train)


def _evaluate_seed(
    prior: Any,
    short: _Split,
    long: _Split,
    samples: int,
    seed: int,
    temperature: float | None,
    recon: dict[str, dict[str, float | None]],
) -> dict[str, Any]:
    """`evaluate`'s table at one sampling seed; ``recon`` caches the reconstruction metrics per key."""
    L, F = short.length, long.length
    train_w, test_w, pca, retrieval = short.train, short.test, short.pca, short.retrieval
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
        if key not in recon:
            rec = prior.reconstruct(real, sk)
            tw = train_w[key][1][
                :: max(1, len(train_w[key][1]) // 64)
            ]  # decoding seen windows: underfit or not
            recon[key] = {
                "recon_mpjpe": M.mpjpe(M.joint_positions(rec, sk), p_real),
                "recon_rot_deg": M.rotation_error_deg(rec, real),
                "recon_amplitude": M.motion_ratio(M.joint_amplitude(rec), M.joint_amplitude(real)),
                "train_recon_amplitude": M.motion_ratio(
                    M.joint_amplitude(prior.reconstruct(tw, sk)), M.joint_amplitude(tw)
                ),
            }
        row["ponymation"].update(recon[key])
        if key in long.test and key in long.train:
            _long_metrics(
                row, prior, sk, long.test[key][1], long.pca, long.retrieval, samples, seed, temperature
            )
        per[key] = row
    table = {m: _mean([per[k][m] for k in per]) for m in METHODS}
    return {
        "skeletons": sorted(per),
        "held_out_windows": int(sum(len(test_w[k][1]) for k in per)),
        "samples_per_skeleton": samples,
        "long_frames": F,
        "units": "joint positions in % of the skeleton's rest diagonal, body frame (no root motion); "
        "mcd in %^2, smoothness in % per frame^2, foot sliding in % per frame; amplitude and speed: "
        f"per-joint ratios to held-out {F}-frame windows (geometric mean over skeletons); gait: feet autocorrelation; seam jump and "
        "the data's 95th percentile in % per frame^2",
        "table": table,
        "per_skeleton": per,
    }


def pca_curve(
    train: Sequence[MotionSequence],
    test: Sequence[MotionSequence],
    length: int,
    fps: float,
    spreads: Sequence[float],
    samples: int = 32,
    seeds: int = 1,
) -> list[dict[str, float]]:
    """MCD and diversity of the PCA baseline at each Gaussian ``spread`` (1: its own), averaged
    over ``seeds`` and skeletons as in `evaluate`'s table: what the baseline scores at the
    prior's diversity, so the two compare at equal diversity."""
    split = _Split(train, test, length, fps)
    train_w, test_w, pca = split.train, split.test, split.pca
    out = []
    for spread in spreads:
        mcd, div = [], []
        for seed in range(max(1, seeds)):
            per = []
            for key, (sk, real) in sorted(test_w.items()):
                if key in train_w:
                    p = M.joint_positions(
                        pca.sample(sk, max(samples, len(real)), seed=seed, spread=spread), sk
                    )
                    per.append((M.motion_chamfer(p, M.joint_positions(real, sk)), M.diversity(p)))
            mcd.append(np.mean([m for m, _ in per]))
            div.append(np.mean([d for _, d in per]))
        out.append({"spread": float(spread), "mcd": float(np.mean(mcd)), "diversity": float(np.mean(div))})
    return out


def _long_metrics(row, prior, sk, real, pca, retrieval, samples, seed, temperature) -> None:
    """Amplitude and speed ratios, gait periodicity and seams on long windows real (N, F, J, 4),
    added to each method's entry of ``row``."""
    n, F = max(samples, len(real)), real.shape[1]
    gen = {
        "ponymation": prior.sample_delta(sk, n, F, seed=seed, temperature=temperature),
        "pca": pca.sample(sk, n, seed=seed),
        "retrieval": retrieval.sample(sk, n, seed=seed),
        "real": real,
    }
    amp_real, speed_real = M.joint_amplitude(real), M.joint_speed(real)
    feet = sk.feet()
    p_real = M.joint_positions(real, sk)
    for name, w in gen.items():
        p = p_real if name == "real" else M.joint_positions(w, sk)
        row[name]["amplitude"] = M.motion_ratio(M.joint_amplitude(w), amp_real)
        row[name]["speed"] = M.motion_ratio(M.joint_speed(w), speed_real)
        row[name]["amplitude_deg"] = float(M.joint_amplitude(w).mean())
        row[name]["gait"] = M.gait_periodicity(p, feet)
        if name == "ponymation" and hasattr(prior, "seams"):
            row[name]["seam_jump"] = M.seam_jump(p, prior.seams(F))
        if name == "real":
            row[name]["jump_p95"] = float(np.percentile(M.frame_jumps(p), 95))


RATIOS = ("amplitude", "speed", "recon_amplitude", "train_recon_amplitude")


def _mean(rows: list[dict[str, float | None]]) -> dict[str, float | None]:
    """Mean over skeletons; ratios by geometric mean, so one skeleton whose held-out clips barely
    move (a ratio of 10) cannot hide another that stands still (0.01)."""
    keys = {k for r in rows for k in r}
    out: dict[str, float | None] = {}
    for k in sorted(keys):
        v = [r[k] for r in rows if r.get(k) is not None]
        if not v:
            out[k] = None
        elif k in RATIOS:
            out[k] = float(np.exp(np.mean(np.log(np.maximum(v, 1e-3)))))
        else:
            out[k] = float(np.mean(v))
    return out


def format_table(result: dict[str, Any]) -> list[list[str]]:
    """Rows for `zooctl.cli._common.print_table` (columns: method and each metric)."""
    rows = []
    for m in METHODS:
        r = result["table"].get(m, {})
        sd = result.get("table_sd", {}).get(m, {})
        cells = [m]
        for k in ("recon_mpjpe", "mcd", "diversity", "amplitude", "speed", "gait", "foot_sliding"):
            v, e = r.get(k), sd.get(k)
            cells.append("-" if v is None else f"{v:.3f}" + ("" if not e else f" ± {e:.2f}"))
        seam = r.get("seam_jump") if m == "ponymation" else r.get("jump_p95") if m == "real" else None
        cells.append("-" if seam is None else f"{seam:.3f}")
        rows.append(cells)
    return rows


TABLE_COLUMNS = [
    ("method", "left"),
    ("recon MPJPE %", "right"),
    ("MCD %^2", "right"),
    ("diversity %", "right"),
    ("amplitude ratio", "right"),
    ("speed ratio", "right"),
    ("gait", "right"),
    ("foot slide %", "right"),
    ("seam jump (real: p95)", "right"),
]
