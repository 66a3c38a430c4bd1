"""Scoring bank assets against query frames (CASA supplement H, with alternatives).

For one embedder, the cosine distance between query frame q and view v of asset a is
``d[a, q, v] = 1 - <e_q, e_v>`` (unit-norm embeddings). An asset's score (lower is better) is one
of these aggregations:

- ``nearest`` (default, CASA-style): for every query frame the distance to the asset's closest
  view, averaged over the frames: ``mean_q min_v d[a, q, v]``. Each frame may match a different
  view (the animal turns during the video), and one bad frame cannot dominate.
- ``kmin``: the mean of the k smallest distances over all (frame, view) pairs (k = ``k``).
- ``min``: the single best (frame, view) pair - fragile, one lucky match wins.
- ``mean``: the mean over all pairs - equals 1 - <mean query, mean view>, pose- and view-blind.

Several embedders are fused per asset (``fusion``): ``zsum`` (default) z-scores each embedder's
asset scores across the candidates and adds them with weights, so embedders with different
distance scales count equally; ``sum`` adds raw distances; ``rank`` adds ranks.
`bench/retrieval.py` measures all of them.
"""

from __future__ import annotations

import numpy as np

from ..errors import UsageError

AGGREGATIONS = ("nearest", "kmin", "min", "mean")
FUSIONS = ("zsum", "sum", "rank")


def distances(query: np.ndarray, views: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """Cosine distances (A, Q, Vmax) float32 of query (Q, D) to views (A, Vmax, D); padding rows are inf."""
    v = np.asarray(views, dtype=np.float32)
    d = 1.0 - np.einsum("qd,avd->aqv", np.asarray(query, np.float32), v, optimize=True)
    valid = np.arange(v.shape[1])[None, :] < np.asarray(counts)[:, None]  # (A, Vmax)
    return np.where(valid[:, None, :], d, np.inf).astype(np.float32)


def aggregate(d: np.ndarray, how: str = "nearest", k: int = 5) -> np.ndarray:
    """(A, Q, V) distances -> (A,) asset scores, lower is better. See the module docstring."""
    if how not in AGGREGATIONS:
        raise UsageError(f"unknown aggregation {how!r}", hint=f"choose one of {', '.join(AGGREGATIONS)}")
    A = d.shape[0]
    if how == "nearest":
        return d.min(2).mean(1)
    if how == "min":
        return d.reshape(A, -1).min(1)
    finite = np.isfinite(d)
    if how == "mean":
        return np.where(finite, d, 0).sum((1, 2)) / np.maximum(finite.sum((1, 2)), 1)
    flat = d.reshape(A, -1)
    kk = max(1, min(k, flat.shape[1]))
    part = np.partition(flat, kk - 1, axis=1)[:, :kk]
    part = np.where(np.isfinite(part), part, np.nan)
    return np.nanmean(part, axis=1)


def best_views(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per asset: the view closest to the query overall (A,), and each frame's closest view (A, Q)."""
    finite = np.isfinite(d)
    n = finite.sum(1)  # (A, V) frames per view: Q for real views, 0 for padding
    mean_over_q = np.where(n > 0, np.where(finite, d, 0).sum(1) / np.maximum(n, 1), np.inf)
    return mean_over_q.argmin(1), d.argmin(2)


def fuse_terms(
    scores: dict[str, np.ndarray], how: str = "zsum", weights: dict[str, float] | None = None
) -> dict[str, np.ndarray]:
    """Each embedder's (A,) term of the fused score (its weighted z-score, raw score or rank);
    `fuse` adds them. `bank search --explain` shows them."""
    if how not in FUSIONS:
        raise UsageError(f"unknown fusion {how!r}", hint=f"choose one of {', '.join(FUSIONS)}")
    terms = {}
    for name, s in scores.items():
        w = 1.0 if weights is None else float(weights.get(name, 1.0))
        s = np.asarray(s, np.float64)
        if how == "rank":
            t = np.argsort(np.argsort(s, kind="stable"), kind="stable").astype(np.float64)
        elif how == "zsum" and len(s) >= 3 and s.std() > 1e-12:
            t = (s - s.mean()) / s.std()
        else:
            t = s
        terms[name] = w * t
    return terms


def fuse(
    scores: dict[str, np.ndarray], how: str = "zsum", weights: dict[str, float] | None = None
) -> np.ndarray:
    """Combine per-embedder (A,) scores (lower is better) into one (A,) score, lower is better."""
    return sum_terms(fuse_terms(scores, how, weights))


def sum_terms(terms: dict[str, np.ndarray]) -> np.ndarray:
    """The fused (A,) score from `fuse_terms`' terms."""
    if not terms:
        raise UsageError("no embedder scores to combine")
    return np.sum(list(terms.values()), axis=0)
