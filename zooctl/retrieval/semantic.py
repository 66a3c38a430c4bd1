"""The semantic term of `bank search`: what the query shows, by the shipped EfficientNet-Lite0's own
ImageNet head, against what each bank asset is (its label, placed in `zooctl.retrieval.taxonomy`).

The query's class distribution is the mean of its crops' ImageNet probabilities over the 398 animal
classes (crops kept within the frame: `zooctl.retrieval.query.classifier_crops`); it is not
renormalised, so a query the classifier does not take for an animal (a stylised render, a blurred
crop) has little mass and the term fades: it is confidence-weighted.
An asset's agreement is the probability that it is among the bank's nearest relatives of the
animal the query shows: for every class, the assets whose labels share the deepest rank any
candidate shares with it (`zooctl.retrieval.taxonomy.agreement`: the species, else the family,
else the order, else the body plan) get its probability (`semantic_scores`). So the taxonomy falls
back by itself: a bear in a bank without bears goes to the carnivores (its order), not to an asset
labelled only "quadruped", and an elephant in a bank without any of its order to every quadruped
alike (appearance decides). Its semantic score is that relative to the best any candidate reaches,
times the query's `confidence`, the probability of its most probable family (`relative_scores`):
the bank's closest animal scores the classifier's confidence whatever rank it shares (a bird for a
swan when the bank has no duck), the others less; a render the classifier spreads over unrelated
classes weighs little. An asset without a label scores 0 (it still competes on appearance). The
fused search score adds ``-weight * score``. Bank labels inferred from rendered views use the same
head: the deepest rank whose most probable taxon holds at least half the views' mean probability.
"""

from __future__ import annotations

from collections.abc import Iterable
from functools import lru_cache
from typing import Any

import numpy as np

from .taxonomy import ANIMAL_CLASSES, Taxon, load_taxonomy, shared_taxon

# Fused-score weight of the semantic term (appearance terms are z-scores): the weight chosen on the
# real videos and the rendered leave-one-out queries of `bench/retrieval.py` together, with the
# leave-one-out choice beside it in BENCHMARKS.md.
SEMANTIC_WEIGHT = 4.0
VIEW_LABEL_MASS = 0.5  # a majority of the views' probability, not a tuned threshold
SEMANTIC_EMBEDDER = "effnet"  # the embedder whose network classifies the query


def class_distribution(probs: np.ndarray) -> np.ndarray:
    """(K, 1000) ImageNet probabilities of K crops -> (398,) mean probability of each animal class."""
    p = np.asarray(probs, np.float64)
    if p.ndim != 2 or p.shape[0] == 0:
        return np.zeros(ANIMAL_CLASSES)
    return p[:, :ANIMAL_CLASSES].mean(0)


@lru_cache(maxsize=1)
def _class_columns() -> dict[str, np.ndarray]:
    """Body plan, order, family and species of the 398 classes, as arrays (vectorised agreement)."""
    tax = load_taxonomy()
    return {k: np.array([getattr(c, k) for c in tax.imagenet], object) for k in RANK_ATTRS}


RANK_ATTRS = ("body_plan", "order", "family", "species")


@lru_cache(maxsize=4096)
def agreement_vector(taxon: Taxon) -> np.ndarray:
    """(398,) agreement of every ImageNet animal class with ``taxon``, divided by 4 (0..1): the
    vectorised `agreement` (the ranks nest, so a class agrees one level per rank it shares)."""
    cols = _class_columns()
    same = {k: cols[k] == getattr(taxon, k) for k in RANK_ATTRS if getattr(taxon, k) is not None}
    level = 1.0 + sum(same.get(k, False) for k in ("order", "family", "species"))
    return np.where(same["body_plan"], level, 0.0).astype(np.float64) / 4.0


@lru_cache(maxsize=4096)
def label_taxon(label: str) -> Taxon | None:
    """The taxon an asset's stored label names (None: not an animal the taxonomy knows)."""
    return load_taxonomy().resolve(label) if label else None


def entry_taxon(entry: dict[str, Any] | None) -> Taxon | None:
    """The taxon of a bank index entry's ``label`` (None without one)."""
    label = entry.get("label") if isinstance(entry, dict) else None
    return label_taxon(label) if isinstance(label, str) else None


def semantic_scores(dist: np.ndarray, taxa: Iterable[Taxon | None]) -> np.ndarray:
    """(A,) for each asset's taxon, the probability of the query distribution ``dist`` (398,) on the
    classes it is among the nearest relatives of: those where it shares the deepest rank any of
    ``taxa`` shares with the class (see the module docstring); 0 for None."""
    taxa = list(taxa)
    kinds = list(dict.fromkeys(t for t in taxa if t is not None))
    if not kinds:
        return np.zeros(len(taxa))
    agree = np.stack([agreement_vector(t) for t in kinds])  # (U, 398)
    best = agree.max(0)
    nearest = (agree == best) & (best > 0)
    score = dict(zip(kinds, nearest.astype(np.float64) @ np.asarray(dist, np.float64)))
    return np.array([0.0 if t is None else score[t] for t in taxa], np.float64)


def confidence(dist: np.ndarray) -> float:
    """How surely the classifier names the query's animal: the probability of its most probable
    family (a real dog: its breeds add up; a stylised render: a little on many unrelated classes)."""
    families = _class_columns()["family"]
    _, idx = np.unique(families.astype(str), return_inverse=True)
    return float(np.bincount(idx, weights=dist).max()) if dist.size else 0.0


def relative_scores(dist: np.ndarray, scores: np.ndarray) -> np.ndarray:
    """The semantic term's scores: each asset's `semantic_scores` relative to the best any asset
    reaches (1: as close as the bank comes to the query's animal), times the query's `confidence`."""
    top = float(scores.max()) if len(scores) else 0.0
    return scores * (confidence(dist) / top) if top > 0 else np.zeros_like(scores)


def top_classes(dist: np.ndarray, n: int = 3) -> list[tuple[str, float]]:
    """The ``n`` most probable animal classes of a query distribution: (class name, probability)."""
    tax = load_taxonomy()
    order = np.argsort(-dist, kind="stable")[:n]
    return [(tax.classes[i], float(dist[i])) for i in order if dist[i] > 0]


def query_taxon(dist: np.ndarray) -> Taxon | None:
    """The animal the query most probably shows: the most probable species of the family with the
    most probability (dog breeds or ducks spread over many classes), None with no animal mass."""
    if dist.size == 0 or float(dist.max()) <= 0:
        return None
    families = _class_columns()["family"]
    names, idx = np.unique(families.astype(str), return_inverse=True)
    best = names[int(np.argmax(np.bincount(idx, weights=dist, minlength=len(names))))]
    return load_taxonomy().imagenet[int(np.argmax(np.where(families == best, dist, -1.0)))]


def matched_taxon(
    dist: np.ndarray, taxon: Taxon | None, query: Taxon | None = None
) -> tuple[str, str] | None:
    """(rank, name) of what an asset's taxon shares with the query's most probable animal
    (``query``: `query_taxon(dist)` when the caller has it)."""
    q = query_taxon(dist) if query is None else query
    return None if q is None or taxon is None else shared_taxon(q, taxon)


def views_taxon(probs: np.ndarray) -> Taxon | None:
    """The label of an asset from its rendered views' ImageNet probabilities ((V, 1000) or their
    (1000,) mean): the deepest rank whose most probable taxon holds `VIEW_LABEL_MASS` of the
    probability; None when no body plan does."""
    p = np.asarray(probs, np.float64)
    p = p.mean(0) if p.ndim == 2 else p
    p = p[:ANIMAL_CLASSES]
    tax = load_taxonomy()
    for rank in ("species", "family", "order", "body plan"):
        key = "body_plan" if rank == "body plan" else rank
        mass: dict[str, float] = {}
        for c, taxon in enumerate(tax.imagenet):
            k = getattr(taxon, key)
            mass[k] = mass.get(k, 0.0) + float(p[c])
        best = max(mass, key=mass.__getitem__)
        if mass[best] >= VIEW_LABEL_MASS:
            return tax.node(rank, best)
    return None
