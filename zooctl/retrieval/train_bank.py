"""The user's bank as extra training data for `zooctl embed train --bank`.

Every bank asset with effnet and silhouette views contributes its stored view features (no
rendering: the packs `bank add` wrote) as one more "animal" for the identity loss, and, when one of
its tags names a body plan, for the body-plan loss too. Tags name a plan by a label of
`zooctl.procedural.random.LABELS` (spaces, '-' or '_' alike: ``biped-dinosaur``) or by a starter
plan (``dinosaur``, through `zooctl.retrieval.evaluate.STARTER_PLANS`).
"""

from __future__ import annotations

import numpy as np

from .evaluate import STARTER_PLANS
from .train_data import FEATURES, TrainingSet


def plan_from_tags(tags: list[str], labels: list[str]) -> str | None:
    """The body-plan label that one of ``tags`` names, else None."""
    for t in tags:
        key = str(t).strip().lower().replace("-", " ").replace("_", " ")
        plan = key if key in labels else STARTER_PLANS.get(key)
        if plan in labels:
            return plan
    return None


def bank_training_set(bank, labels: list[str]) -> TrainingSet:
    """Stored view features of every bank asset that has views for all of `FEATURES`; its label is
    the plan its tags name (-1 when none)."""
    from ..errors import UsageError
    from .index import current_pack

    entries = bank.list()
    packs = {f: current_pack(bank, f, entries)[0] for f in FEATURES}
    names = sorted(set.intersection(*(set(p.names) if p is not None else set() for p in packs.values())))
    if not names:
        raise UsageError(
            f"no asset in the bank has views for {' and '.join(FEATURES)}",
            hint="add assets with `zooctl bank add`, or run `zooctl bank reindex`",
        )
    tags = {e["name"]: e.get("tags", []) for e in entries}
    feats: dict[str, list[np.ndarray]] = {f: [] for f in FEATURES}
    lab, ani = [], []
    for i, n in enumerate(names):
        counts = []
        for f, p in packs.items():
            row = p.positions()[n]
            feats[f].append(np.asarray(p.emb[row, : p.counts[row]], np.float32))
            counts.append(int(p.counts[row]))
        k = min(counts)
        for f in FEATURES:
            feats[f][-1] = feats[f][-1][:k]
        plan = plan_from_tags(tags.get(n, []), labels)
        lab.append(np.full(k, labels.index(plan) if plan else -1))
        ani.append(np.full(k, i))
    return TrainingSet(
        {f: np.concatenate(v) for f, v in feats.items()},
        np.concatenate(lab).astype(np.int64),
        np.concatenate(ani).astype(np.int64),
        labels,
    )
