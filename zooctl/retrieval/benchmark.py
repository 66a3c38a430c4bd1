"""Retrieval benchmarks behind `zooctl bench retrieval` and `bench/retrieval.py`.

- `loo_benchmark`: index a set of assets into a fresh bank (timing each asset's views +
  embeddings: the `bank add` overhead), render a query video of each, and report leave-one-out
  accuracy (`zooctl.retrieval.evaluate`) per embedder, for the combination, and per aggregation.
- `search_latency`: a bank of N synthetic assets (random unit embeddings in the real pack
  format), timing the scoring of one query (median).
"""

from __future__ import annotations

import itertools
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

from .evaluate import leave_one_out, render_query_video
from .index import cached_embedder, embed_inputs, index_asset
from .score import AGGREGATIONS, FUSIONS
from .views import DEFAULT_SIZE, DEFAULT_VIEWS


def loo_benchmark(
    assets: list,
    root: Path,
    embedders: list[str],
    n_views: int = DEFAULT_VIEWS,
    size: int = DEFAULT_SIZE,
    frames: int = 8,
    seed: int = 0,
    device: str = "cpu",
    progress=None,
    queries: list[str] | None = None,
    semantic_weights: list[float] | None = None,
    styles: list[str] | None = None,
) -> dict[str, Any]:
    """Leave-one-out retrieval over ``assets`` in a new bank at ``root``. See the module docstring.

    ``queries``: names of the assets to query (default: all); the rest are only bank content.
    Query i of ``queries`` is rendered with the same seed whatever else the bank holds.
    ``semantic_weights``: also score the default search (every embedder, nearest, zsum) with the
    semantic term at each of these weights (`zooctl.retrieval.semantic`); the assets are labelled
    as `bank add` labels them (name, tags, else views). ``styles``: also query each asset with renders
    in these held-out styles (`zooctl.retrieval.styles`; the same clip and camera as its plain
    query), scored like the semantic runs (at weight 0 too) under ``heldout``."""
    from ..store.bank import Bank
    from .labels import label_asset
    from .search import classify_query

    bank = Bank(root)
    index_s = []
    for i, a in enumerate(assets):
        label_asset(a)
        bank.add(a, replace=True)
        t = time.perf_counter()
        index_asset(bank, a, embedders, n_views=n_views, size=size, seed=seed, device=device)
        index_s.append(time.perf_counter() - t)
        if progress:
            progress(f"indexed {a.name} ({index_s[-1]:.2f} s)", i + 1, len(assets))
    q_emb: dict[str, dict[str, np.ndarray]] = {}
    q_classes: dict[str, np.ndarray] = {}
    names = [a.name for a in assets] if queries is None else list(queries)
    by_name = {a.name: a for a in assets}
    for i, a in enumerate(by_name[n] for n in names):
        q = render_query_video(a, n_frames=frames, size=size, seed=1000 + seed * 7919 + i, device=device)
        q_emb[a.name] = {e: embed_inputs(cached_embedder(e, device), q.images, q.masks) for e in embedders}
        if semantic_weights:
            q_classes[a.name] = classify_query(cached_embedder("effnet", device), q)
    heldout: dict[str, dict[str, Any]] = {}
    for style in styles or []:
        emb_s: dict[str, dict[str, np.ndarray]] = {}
        cls_s: dict[str, np.ndarray] = {}
        for i, a in enumerate(by_name[n] for n in names):
            seed_i = 1000 + seed * 7919 + i
            q = render_query_video(a, n_frames=frames, size=size, seed=seed_i, device=device, style=style)
            eff = cached_embedder("effnet", device)
            emb_s[a.name] = {
                e: embed_inputs(cached_embedder(e, device), q.images, q.masks) for e in embedders
            }
            cls_s[a.name] = classify_query(eff, q)
        if progress:
            progress(f"held-out style {style}", len(heldout) + 1, len(styles))
        heldout[style] = {
            str(w): leave_one_out(
                bank, assets, emb_s, embedders, queries=set(names), query_classes=cls_s, semantic_weight=w
            ).to_json()
            for w in sorted({0.0, *(semantic_weights or [])})
        }
    results = []
    # Every embedder alone and every combination of them (7 sets for 3 embedders).
    sets = [list(c) for k in range(1, len(embedders) + 1) for c in itertools.combinations(embedders, k)]
    for es in sets:
        for agg in AGGREGATIONS:
            for fusion in FUSIONS if len(es) > 1 else ("zsum",):
                r = leave_one_out(bank, assets, q_emb, es, aggregation=agg, fusion=fusion, queries=set(names))
                results.append(r.to_json())
    semantic = {}
    for w in semantic_weights or []:
        r = leave_one_out(
            bank, assets, q_emb, embedders, queries=set(names), query_classes=q_classes, semantic_weight=w
        )
        semantic[str(w)] = r.to_json()
    return {
        "semantic": semantic,
        "heldout": heldout,
        "labels": {s["name"]: s.get("label") for s in bank.list()},
        "assets": len(assets),
        "queries": len(names),
        "views": n_views,
        "size": size,
        "frames": frames,
        "index_seconds_per_asset_median": statistics.median(index_s) if index_s else None,
        "index_seconds_per_asset_max": max(index_s) if index_s else None,
        "results": results,
    }


COLUMNS = [
    ("embedders", "left"),
    ("aggregation", "left"),
    ("fusion", "left"),
    ("top-1 plan", "right"),
    ("top-1 answerable", "right"),
    ("top-3 plan", "right"),
    ("top-1 skeleton", "right"),
]


def summary_rows(report: dict[str, Any]) -> list[list[str]]:
    """Table rows in `COLUMNS` order."""
    rows = []
    for r in report["results"]:
        sk = (
            "-"
            if r["top1_skeleton"] is None
            else f"{100 * r['top1_skeleton']:.0f}% of {r['skeleton_queries']}"
        )
        ans = "-" if r["top1_plan_answerable"] is None else f"{100 * r['top1_plan_answerable']:.0f}%"
        rows.append(
            [
                "+".join(r["embedders"]),
                r["aggregation"],
                r["fusion"] if len(r["embedders"]) > 1 else "-",
                f"{100 * r['top1_plan']:.0f}%",
                ans,
                f"{100 * r['top3_plan']:.0f}%",
                sk,
            ]
        )
    return rows


def synthetic_bank(
    root: Path, n_assets: int, dims: dict[str, int], n_views: int = DEFAULT_VIEWS, seed: int = 0
) -> None:
    """Write a bank index of ``n_assets`` synthetic entries with views, and one pack per embedder of
    random unit embeddings (float16), exactly as `current_pack` would have built them."""
    from ..store import views_h5
    from ..store.bank import INDEX_VERSION, Bank
    from ..store.fs import write_json_atomic

    rng = np.random.default_rng(seed)
    names = [f"synthetic{i:06d}" for i in range(n_assets)]
    ids = {n: f"id{i:06d}" for i, n in enumerate(names)}
    entry = {
        "vertices": 1000,
        "faces": 2000,
        "joints": 20,
        "clips": {},
        "bbox": [[0, 0, 0], [1, 1, 1]],
        "tags": ["synthetic"],
        "license": "CC0-1.0",
        "source": "synthetic",
        "has_texture": False,
    }
    index = {
        "schema_version": INDEX_VERSION,
        "assets": {
            n: {
                **entry,
                "name": n,
                "views": {"count": n_views, "size": DEFAULT_SIZE, "embedders": dims, "views_id": ids[n]},
            }
            for n in names
        },
    }
    bank = Bank(root)
    bank.dir.mkdir(parents=True, exist_ok=True)
    write_json_atomic(bank.index_path, index)
    for e, D in dims.items():
        emb = np.empty((n_assets, n_views, D), np.float16)
        for s in range(0, n_assets, 1000):  # in slices: bounded float32 temporaries
            x = rng.normal(size=(min(1000, n_assets - s), n_views, D)).astype(np.float32)
            emb[s : s + len(x)] = x / np.linalg.norm(x, axis=-1, keepdims=True)
        views_h5.write_pack(root, e, names, np.full(n_assets, n_views), emb, ids)


def search_latency(
    root: Path, dims: dict[str, int], frames: int = 8, repeat: int = 7, seed: int = 1, **options: Any
) -> dict[str, float]:
    """Median seconds for one random query against the bank at ``root``: ``scoring_s`` (both
    stages of `score_packs`) and ``load_s`` (reading the index and checking the packs)."""
    from ..store.bank import Bank
    from .search import load_packs, score_packs

    rng = np.random.default_rng(seed)
    q = {e: rng.normal(size=(frames, D)).astype(np.float32) for e, D in dims.items()}
    q = {e: v / np.linalg.norm(v, axis=1, keepdims=True) for e, v in q.items()}
    bank = Bank(root)
    packs, _ = load_packs(bank, list(q))  # warm: page cache, packs validated
    score_packs(packs, q, **options)
    load, scoring = [], []
    for _ in range(repeat):
        t = time.perf_counter()
        packs, _ = load_packs(bank, list(q))
        t1 = time.perf_counter()
        score_packs(packs, q, **options)
        scoring.append(time.perf_counter() - t1)
        load.append(t1 - t)
    return {"scoring_s": statistics.median(scoring), "load_s": statistics.median(load)}
