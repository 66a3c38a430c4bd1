"""The semantic term's benchmark (`bench/retrieval.py`): retrieval of real videos by body plan and
family, and the fusion weight chosen leave-one-out over real and rendered queries.

Truth comes from label files the bank never sees (``videos/labels.json``, ``assets/labels.json``
of the shared data; a starter animal's truth is its generated body plan): the bank's own labels
are the ones a user's would have (name, tags, views). A video's family is *right* when the top
result agrees with it at the deepest rank any asset of the bank reaches (family when the bank
holds one of its family, else order, else body plan): "the nearest order" for a bear or an
elephant when the bank has no bear or elephant.
"""

from __future__ import annotations

from typing import Any

from .evaluate import STARTER_PLANS

RANK_KEYS = ("family", "order", "body_plan")


def _plan(p: str | None) -> str | None:
    return {"fish-like swimmer": "fish"}.get(p, p) if p else p


def asset_truth(name: str, meta: Any, asset_labels: dict[str, dict]) -> dict[str, str | None]:
    """{family, order, body_plan} of a bank asset for scoring (None where unknown)."""
    if name in asset_labels:
        t = asset_labels[name]
        known = {k: (None if t.get(k) in (None, "unknown") else t.get(k)) for k in RANK_KEYS}
        return {**known, "body_plan": _plan(known["body_plan"])}
    plan = meta.get("body_plan") if isinstance(meta, dict) else None
    return {"family": None, "order": None, "body_plan": STARTER_PLANS.get(plan, plan) if plan else None}


def reachable_rank(video: dict[str, str], truths: dict[str, dict]) -> str | None:
    """The deepest of family, order, body plan at which some bank asset agrees with the video."""
    for k in RANK_KEYS:
        if any(t[k] is not None and t[k] == _plan(video.get(k)) for t in truths.values()):
            return k
    return None


def judge(video: dict[str, str], top: list[str], truths: dict[str, dict]) -> dict[str, Any]:
    """Body plan and family (at the reachable rank) right at top-1 and within the top 3."""
    rank = reachable_rank(video, truths)

    def ok(name: str, key: str | None) -> bool:
        return key is not None and truths.get(name, {}).get(key) == _plan(video.get(key))

    return {
        "top": top[:3],
        "rank": rank,
        "plan1": ok(top[0], "body_plan") if top else False,
        "plan3": any(ok(n, "body_plan") for n in top[:3]),
        "family1": ok(top[0], rank) if top else False,
        "family3": any(ok(n, rank) for n in top[:3]),
    }


def choose_loo(
    points: dict[float, dict[str, float]], queries: list[str]
) -> tuple[float, dict[str, float], dict[str, float]]:
    """Choose a weight in-sample and leave-one-out. ``points[w][q]``: query q's score at weight w
    (higher is better). Returns (the in-sample weight, {q: in-sample score}, {q: the score at the
    weight chosen on every other query}). Ties go to the smaller weight."""
    weights = sorted(points)

    def best(skip: str | None) -> float:
        return max(weights, key=lambda w: (sum(v for q, v in points[w].items() if q != skip), -w))

    w_in = best(None)
    return w_in, {q: points[w_in][q] for q in queries}, {q: points[best(q)][q] for q in queries}
