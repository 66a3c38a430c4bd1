"""Evaluating `procnet` heads on cached frozen features (`bench/procnet.py`).

`render_features` renders what the leave-one-out benchmark renders (`zooctl.retrieval.benchmark`:
each asset's bank views with the seed `bank add` uses, query video i with seed 1000 + i) for a set
of model files and the starter bank, plus a procedural held-out set of another seed than training,
and keeps only the frozen effnet and silhouette features. `evaluate_weights` then scores a head
in seconds: `nearest` aggregation and `zsum` fusion, as `zooctl bank search` does.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .evaluate import body_plan
from .score import aggregate, fuse
from .train_data import FEATURES, TrainingSet

HELD_OUT_ANIMALS = 60  # 6 per body plan, seed 1
HELD_OUT_SEED = 1
HELD_OUT_QUERY_VIEWS = 4


@dataclass
class FrozenFeatures:
    """Frozen features of the benchmark renders.

    bank[f] (A, V, D) and query[f] (A, Q, D) for the A model files (``names``, ``plans``);
    starter[f] (S, V, D) for the starter animals; held_out: the procedural held-out `TrainingSet`.
    """

    names: list[str]
    plans: list[str | None]
    bank: dict[str, np.ndarray]
    query: dict[str, np.ndarray]
    starter_names: list[str]
    starter_plans: list[str | None]
    starter: dict[str, np.ndarray]
    held_out: TrainingSet


def _features(images: np.ndarray, masks: np.ndarray) -> dict[str, np.ndarray]:
    from .index import cached_embedder

    return {
        "effnet": cached_embedder("effnet").embed_batch(images),
        "silhouette": cached_embedder("silhouette").embed_batch(masks),
    }


def render_features(files: list[Path], held_out: int = HELD_OUT_ANIMALS, progress=None) -> FrozenFeatures:
    """Render and reduce to frozen features (see the module docstring); slow (minutes)."""
    from ..io.gltf_import import load_gltf
    from ..procedural import starter_assets
    from .evaluate import render_query_video
    from .index import view_seed
    from .train_data import render_training_set
    from .views import render_views

    def views_of(assets: list) -> dict[str, np.ndarray]:
        out: dict[str, list] = {f: [] for f in FEATURES}
        for a in assets:
            vs = render_views(a, seed=view_seed(a.name, 0))
            for f, x in _features(vs.images, vs.masks).items():
                out[f].append(x)
            if progress:
                progress(f"views of {a.name}")
        return {f: np.stack(v) for f, v in out.items()}

    assets = [load_gltf(f, f.stem) for f in files]
    starter = starter_assets()
    bank = views_of(assets)
    query: dict[str, list] = {f: [] for f in FEATURES}
    for i, a in enumerate(assets):
        q = render_query_video(a, n_frames=8, seed=1000 + i)
        for f, x in _features(q.images, q.masks).items():
            query[f].append(x)
        if progress:
            progress(f"query of {a.name}")
    return FrozenFeatures(
        [a.name for a in assets],
        [body_plan(a) for a in assets],
        bank,
        {f: np.stack(v) for f, v in query.items()},
        [a.name for a in starter],
        [body_plan(a) for a in starter],
        views_of(starter),
        render_training_set(held_out, 12, seed=HELD_OUT_SEED),
    )


def save_features(path: Path, ff: FrozenFeatures) -> Path:
    """Write ``ff`` as one ``.npz`` (atomic)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = {
        "names": np.array(ff.names),
        "plans": np.array([p or "" for p in ff.plans]),
        "starter_names": np.array(ff.starter_names),
        "starter_plans": np.array([p or "" for p in ff.starter_plans]),
        "ho_label": ff.held_out.label,
        "ho_animal": ff.held_out.animal,
        "ho_labels": np.array(ff.held_out.labels),
    }
    for f in FEATURES:
        arrays[f"bank_{f}"] = ff.bank[f]
        arrays[f"query_{f}"] = ff.query[f]
        arrays[f"starter_{f}"] = ff.starter[f]
        arrays[f"ho_{f}"] = ff.held_out.features[f]
    tmp = path.with_name(f".{path.stem}.tmp{os.getpid()}.npz")
    np.savez(tmp, **arrays)
    os.replace(tmp, path)
    return path


def load_features(path: Path) -> FrozenFeatures:
    z = np.load(path)

    def strs(k: str) -> list:
        return [str(s) or None for s in z[k]]

    return FrozenFeatures(
        strs("names"),
        strs("plans"),
        {f: z[f"bank_{f}"] for f in FEATURES},
        {f: z[f"query_{f}"] for f in FEATURES},
        strs("starter_names"),
        strs("starter_plans"),
        {f: z[f"starter_{f}"] for f in FEATURES},
        TrainingSet(
            {f: z[f"ho_{f}"] for f in FEATURES},
            z["ho_label"],
            z["ho_animal"],
            [str(s) for s in z["ho_labels"]],
        ),
    )


def nearest_scores(query: np.ndarray, views: np.ndarray) -> np.ndarray:
    """Query (Q, D) against views (A, V, D) -> (A,) `nearest` scores (unit rows, lower is better)."""
    d = 1.0 - np.einsum("qd,avd->aqv", query, views, optimize=True)
    return aggregate(d, "nearest")


def rank_query(
    query: dict[str, np.ndarray], views: dict[str, np.ndarray], keep: np.ndarray, embedders: list[str]
) -> np.ndarray:
    """Candidate indices (into ``keep``, a boolean (A,) mask) best first, fusing ``embedders`` by zsum."""
    idx = np.flatnonzero(keep)
    scores = {e: nearest_scores(query[e], views[e][idx]) for e in embedders}
    return idx[np.argsort(fuse(scores, "zsum"), kind="stable")]


def _empty_row() -> dict[str, Any]:
    return {"queries": 0, "top1": 0, "top3": 0, "answerable": 0, "top1_answerable": 0, "misses": []}


def _tally(row: dict[str, Any], names: list[str], plans: list, i: int, order: np.ndarray, others) -> None:
    """Count query i, ranked ``order`` (candidate indices, best first) among ``others``, into ``row``."""
    got = [plans[j] for j in order[:3]]
    answerable = any(plans[j] == plans[i] for j in others)
    row["queries"] += 1
    row["top1"] += got[0] == plans[i]
    row["top3"] += plans[i] in got
    row["answerable"] += answerable
    row["top1_answerable"] += answerable and got[0] == plans[i]
    if got[0] != plans[i]:
        row["misses"].append(f"{names[i]}->{names[order[0]]}")


def loo_rows(
    names: list[str],
    plans: list[str | None],
    queries: dict[str, np.ndarray],
    views: dict[str, np.ndarray],
    embedders: list[str],
    n_query: int,
) -> dict[str, Any]:
    """Leave-one-out over the first ``n_query`` entries: {queries, top1, top3, answerable,
    top1_answerable, misses}. ``views`` holds every entry (the queries first); queries[e] (n_query, Q, D)."""
    A = len(names)
    row = _empty_row()
    for i in range(n_query):
        if plans[i] is None:
            continue
        keep = np.ones(A, bool)
        keep[i] = False
        order = rank_query({e: queries[e][i] for e in embedders}, views, keep, embedders)
        _tally(row, names, plans, i, order, (j for j in range(A) if j != i))
    return row


def held_out_rows(ts: TrainingSet, emb: dict[str, np.ndarray], embedders: list[str]) -> dict[str, Any]:
    """Each held-out animal's first views as the query, the other animals' views as the bank."""
    animals = np.unique(ts.animal)
    views = {e: np.stack([emb[e][ts.animal == a] for a in animals]) for e in embedders}
    plans = [ts.labels[int(ts.label[ts.animal == a][0])] for a in animals]
    queries = {e: views[e][:, :HELD_OUT_QUERY_VIEWS] for e in embedders}
    return loo_rows([str(a) for a in animals], plans, queries, views, embedders, len(animals))


def head_embeddings(
    weights: dict[str, np.ndarray], inputs: list[str], feats: dict[str, np.ndarray]
) -> np.ndarray:
    """(..., Din) frozen features by name -> (..., dim) procnet embeddings."""
    from ..embed.procnet import apply_head

    x = np.concatenate([feats[f] for f in inputs], -1)
    shape = x.shape[:-1]
    dim = weights["w2"].shape[1]
    return apply_head(weights, x.reshape(-1, x.shape[-1]).astype(np.float32)).reshape(*shape, dim)


SETS = (["effnet", "silhouette"], ["procnet"], ["effnet", "procnet"], ["effnet", "silhouette", "procnet"])


def evaluate_weights(ff: FrozenFeatures, weights: Path | None) -> dict[str, Any]:
    """Rows per (set, embedders): shared leave-one-out, shared + starter, procedural held-out."""
    rows = []
    sets = [SETS[0]]
    emb_bank = dict(ff.bank)
    emb_query = dict(ff.query)
    emb_starter = dict(ff.starter)
    emb_ho = dict(ff.held_out.features)
    if weights is not None:
        from ..embed.procnet import load_head

        w, info = load_head(Path(weights))
        inputs = list(info.get("inputs", FEATURES))
        emb_bank["procnet"] = head_embeddings(w, inputs, ff.bank)
        emb_query["procnet"] = head_embeddings(w, inputs, ff.query)
        emb_starter["procnet"] = head_embeddings(w, inputs, ff.starter)
        emb_ho["procnet"] = head_embeddings(w, inputs, ff.held_out.features)
        sets = list(SETS)
    n = len(ff.names)
    for es in sets:
        both = {e: np.concatenate([emb_bank[e], emb_starter[e]]) for e in es}
        for name, r in (
            ("shared", loo_rows(ff.names, ff.plans, emb_query, emb_bank, es, n)),
            (
                "shared+starter",
                loo_rows(ff.names + ff.starter_names, ff.plans + ff.starter_plans, emb_query, both, es, n),
            ),
            ("held-out", held_out_rows(ff.held_out, emb_ho, es)),
        ):
            rows.append({"set": name, "embedders": "+".join(es), **r})
    return {"rows": rows}


def loo_adapted(
    ff: FrozenFeatures,
    ts: TrainingSet,
    init: dict[str, np.ndarray] | None,
    cfg,
    tagged: bool = True,
    progress=None,
) -> dict[str, Any]:
    """`embed train --bank`, strictly leave-one-out: for each shared query, a head trained on the
    procedural set plus the *other* assets' bank views (their body plans as tags when ``tagged``,
    identity only otherwise), then that query searched among them. Rows as `evaluate_weights`."""
    from .train_embedder import train_head

    inputs = list(cfg.inputs)
    n = len(ff.names)
    labels = list(ts.labels)
    sets = [["procnet"], ["effnet", "procnet"], ["effnet", "silhouette", "procnet"]]
    out = {"+".join(es): _empty_row() for es in sets}
    for i in range(n):
        if ff.plans[i] is None:
            continue
        others = [j for j in range(n) if j != i]
        V = ff.bank[FEATURES[0]].shape[1]
        bank = TrainingSet(
            {f: ff.bank[f][others].reshape(-1, ff.bank[f].shape[-1]) for f in FEATURES},
            np.repeat(
                [labels.index(ff.plans[j]) if tagged and ff.plans[j] in labels else -1 for j in others], V
            ).astype(np.int64),
            np.repeat(np.arange(len(others)), V).astype(np.int64),
            labels,
        )
        w, _ = train_head(ts, cfg, bank=bank, init=init)
        emb_bank = {**ff.bank, "procnet": head_embeddings(w, inputs, ff.bank)}
        emb_q = {**ff.query, "procnet": head_embeddings(w, inputs, ff.query)}
        for es in sets:
            keep = np.ones(n, bool)
            keep[i] = False
            order = rank_query({e: emb_q[e][i] for e in es}, emb_bank, keep, es)
            _tally(out["+".join(es)], ff.names, ff.plans, i, order, others)
        if progress:
            progress(f"fold {ff.names[i]}")
    return {"rows": [{"set": "shared", "embedders": k, **v} for k, v in out.items()]}
