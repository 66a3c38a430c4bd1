"""Sampling temperature calibrated on the training windows.

The trained VAE decodes z ~ N(0, I) into motions less varied than the data, and
scaling the prior's standard deviation by a temperature widens them without leaving the data:
`calibrate_temperature` picks, from a grid, the temperature whose samples are as diverse as the
training windows themselves (mean pairwise joint-position distance, `metrics.diversity`), per
skeleton and then averaged in log ratio. What it picks and how little the held-out clips' motion
Chamfer distance moves around it: BENCHMARKS.md, Motion prior.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import metrics as M

GRID = (
    0.5,
    0.75,
    1.0,
    1.25,
    1.5,
    2.0,
    2.5,
    3.0,
    3.5,
    4.0,
    5.0,
    6.0,
    8.0,
)  # an under-trained prior needs more than 4


def calibrate_temperature(
    prior: Any,
    dataset: Any,
    grid: tuple[float, ...] = GRID,
    skeletons: int = 6,
    windows: int = 48,
    samples: int = 16,
    seed: int = 0,
) -> dict[str, Any]:
    """{"temperature", "real_diversity", "diversity": {T: d}} for a `PonymationPrior` and the
    `MotionDataset` it was trained on; uses the ``skeletons`` skeletons with most windows, up to
    ``windows`` real windows and ``samples`` sampled windows each."""
    rng = np.random.default_rng(seed)
    ids = np.asarray(dataset.skel_ids)
    counts = np.bincount(ids, minlength=len(dataset.skeletons))
    chosen = [int(s) for s in np.argsort(-counts, kind="stable")[:skeletons] if counts[s] > 1]
    real_div, gen_div = [], {t: [] for t in grid}
    for sid in chosen:
        sk = dataset.skeletons[sid]
        pick = rng.permutation(np.flatnonzero(ids == sid))[:windows]
        rot6d = dataset.batch(pick).rot6d[:, :, : sk.num_joints]
        real = M.diversity(M.joint_positions(prior._to_quat(rot6d), sk))
        if not real > 0:
            continue
        real_div.append(real)
        for t in grid:
            w = prior.sample_delta(sk, samples, dataset.length, seed=seed, temperature=t)
            gen_div[t].append(M.diversity(M.joint_positions(w, sk)))
    if not real_div:
        return {"temperature": 1.0, "real_diversity": None, "diversity": {}}
    err = {t: float(np.mean(np.abs(np.log(np.maximum(gen_div[t], 1e-9) / np.array(real_div))))) for t in grid}
    best = min(grid, key=lambda t: (err[t], t))
    return {
        "temperature": float(best),
        "real_diversity": round(float(np.mean(real_div)), 4),
        "diversity": {str(t): round(float(np.mean(gen_div[t])), 4) for t in grid},
    }
