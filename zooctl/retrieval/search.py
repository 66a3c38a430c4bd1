"""`bank search`: rank the bank's assets by how well their rendered views match query frames.

Per embedder: embed the K query crops, take the bank's pack (A, Vmax, D), score every asset
(`zooctl.retrieval.score`), then fuse embedders. Banks larger than ``shortlist`` assets are scored
in two stages: every asset by its *mean* view embedding (one (K, D) x (D, A) product per embedder,
fused), then the best ``shortlist`` exactly. With ``shortlist`` >= the bank size the result is exact.
Scoring is numpy only (one BLAS product per embedder and stage): a search whose query embeddings
are cached (`query_embeddings`, stored videos) never imports torch.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..embed.base import embedder_identity
from ..errors import UsageError
from . import query_cache
from .index import cached_embedder, current_pack, embed_inputs, enabled_embedders, needs_masks
from .query import DEFAULT_QUERY_FRAMES, QueryFrames, load_query, stored_query
from .score import aggregate, best_views, fuse, fuse_terms, sum_terms
from .semantic import (
    SEMANTIC_EMBEDDER,
    SEMANTIC_WEIGHT,
    class_distribution,
    entry_taxon,
    matched_taxon,
    query_taxon,
    relative_scores,
    semantic_scores,
    top_classes,
)

DEFAULT_TOP = 5
DEFAULT_SHORTLIST = 256


@dataclass
class Match:
    """One ranked asset: fused ``score`` (lower is better), per-embedder ``distances`` (the chosen
    aggregation of cosine distances), its ``best_view`` overall and each query frame's nearest view.
    Per embedder also its ``terms`` of the fused score (they add up to ``score``) and the asset's
    ``ranks`` by that embedder alone among the scored candidates (1: best). With the semantic term
    (`zooctl.retrieval.semantic`): the asset's ``label``, its ``semantic`` score (0..1: how surely
    it is among the bank's nearest relatives of the animal; its term is ``terms["semantic"]``) and
    ``taxon``, what its label shares with the query's most probable species ([rank, name]) or None."""

    name: str
    score: float
    distances: dict[str, float]
    best_view: int
    frame_views: list[int]
    terms: dict[str, float] = field(default_factory=dict)
    ranks: dict[str, int] = field(default_factory=dict)
    label: str | None = None
    semantic: float | None = None
    taxon: list[str] | None = None


@dataclass
class SearchResult:
    matches: list[Match]
    embedders: list[str]
    aggregation: str
    fusion: str
    candidates: int
    notes: list[str] = field(default_factory=list)
    classes: list[tuple[str, float]] = field(default_factory=list)  # the query's top animal classes
    semantic_weight: float | None = None  # None: no semantic term (no classes, or weight 0)

    def to_json(self) -> dict[str, Any]:
        return {
            "embedders": self.embedders,
            "aggregation": self.aggregation,
            "fusion": self.fusion,
            "candidates": self.candidates,
            "notes": self.notes,
            "classes": [{"class": c, "probability": p} for c, p in self.classes],
            "semantic_weight": self.semantic_weight,
            "matches": [
                {
                    "rank": i + 1,
                    "name": m.name,
                    "score": m.score,
                    "distances": m.distances,
                    "best_view": m.best_view,
                    "frame_views": m.frame_views,
                    "terms": m.terms,
                    "ranks": m.ranks,
                    "label": m.label,
                    "semantic": m.semantic,
                    "taxon": m.taxon,
                }
                for i, m in enumerate(self.matches)
            ],
        }


def embed_query(
    query: QueryFrames, embedders: list[str], device: str = "cpu"
) -> tuple[dict[str, np.ndarray], list[str]]:
    """{embedder: (K, D)} for the embedders the query can feed; notes for the ones it cannot.
    Records each embedder's identity in ``query.identities``."""
    out, notes = {}, []
    for e in embedders:
        emb = cached_embedder(e, device)
        if needs_masks(emb) and query.masks is None:
            notes.append(f"{e}: skipped, the query has no masks")
            continue
        if e == SEMANTIC_EMBEDDER and hasattr(emb, "embed_and_classify") and len(query.images):
            out[e], probs = emb.embed_and_classify(query.images)  # one pass for both
            query.classes = classify_query(emb, query, probs)
        else:
            out[e] = embed_inputs(emb, query.images, query.masks)
        query.identities[e] = embedder_identity(emb)
    return out, notes


def classify_query(emb: Any, query: QueryFrames, probs: np.ndarray | None = None) -> np.ndarray:
    """(K, 1000) ImageNet probabilities of the query for the semantic term: of its
    ``class_images`` where it has them, else of its ``images``. ``probs``: the classes of
    ``images`` from the embedding's pass, kept for every crop the classifier's crop equals."""
    ci = query.class_images
    if probs is None:
        return emb.classify(query.images if ci is None else ci)
    if ci is None or len(ci) != len(probs):
        return probs
    differ = [i for i in range(len(ci)) if not np.array_equal(ci[i], query.images[i])]
    if differ:
        probs = np.array(probs, copy=True)
        probs[differ] = emb.classify(ci[differ])
    return probs


def _stored_video(source: Any, masks_dir: Any, store_root: Any):
    """The `VideoStore` holding ``source`` when it names a stored video (and no file), else None."""
    if store_root is None or masks_dir is not None or Path(str(source)).expanduser().exists():
        return None
    from ..store.videos import VideoStore

    videos = VideoStore(store_root)
    return videos if videos.exists(str(source)) else None


class EmbedderMismatch(UsageError):
    """The bank's views and the query were embedded by different versions of one embedder."""

    def __init__(self, embedder: str, message: str):
        super().__init__(message, hint=f"run `zooctl bank reindex --embedder {embedder}`")
        self.embedder = embedder


class DimensionMismatch(EmbedderMismatch):
    """The bank's views and the query were embedded by embedders of different output sizes."""

    def __init__(self, embedder: str, bank_dim: int, query_dim: int):
        super().__init__(
            embedder,
            f"the bank's {embedder} views are {bank_dim}-dimensional but the query's {embedder} "
            f"embeddings are {query_dim}-dimensional: the {embedder} embedder changed since the views were made",
        )


def check_identities(entries: list[dict[str, Any]], embedder: str, query_identity: str | None) -> None:
    """Refuse to compare a query with views that another version of ``embedder`` made (other weights
    of the same size), and a bank whose views mix versions. ``entries``: `Bank.list()`; views
    without a recorded identity (older banks) are not checked."""
    seen: dict[str, int] = {}
    for s in entries:
        views = s.get("views")
        ident = views.get("identities", {}).get(embedder) if isinstance(views, dict) else None
        if ident:
            seen[ident] = seen.get(ident, 0) + 1
    if query_identity is not None:
        stale = sum(n for i, n in seen.items() if i != query_identity)
        if stale:
            raise EmbedderMismatch(
                embedder,
                f"{stale} of the bank's assets have {embedder} views made by another version of the "
                f"{embedder} embedder (other weights or options) than the one embedding the query",
            )
    elif len(seen) > 1:
        raise EmbedderMismatch(
            embedder,
            f"the bank's {embedder} views were made by {len(seen)} different versions of the embedder",
        )


def query_embeddings(
    source: Any,
    embedders: list[str],
    k: int = DEFAULT_QUERY_FRAMES,
    size: int = 224,
    masks_dir: Any = None,
    store_root: Any = None,
    device: str = "cpu",
    need_images: bool = False,
    refresh: set[str] | None = None,
) -> tuple[QueryFrames, dict[str, np.ndarray], list[str]]:
    """Load and embed a query (see `load_query` for ``source``): (query, {embedder: (K, D)}, notes).

    A stored video's embeddings are cached beside it (`zooctl.retrieval.query_cache`): a repeat
    search decodes nothing and builds no embedder; its query then has no pixels (``images`` is
    (0, S, S, 3)) unless ``need_images``. Embedders in ``refresh`` are embedded again even when
    cached (the cache is updated).
    """
    if k < 1:
        raise UsageError(f"--frames {k} must be at least 1")
    videos = _stored_video(source, masks_dir, store_root)
    if videos is None:
        query = load_query(source, k=k, size=size, masks_dir=masks_dir, store_root=store_root)
        emb, notes = embed_query(query, embedders, device)
        return query, emb, notes
    name = str(source)
    identity = query_cache.video_identity(videos, name)
    hit = query_cache.read_cache(videos, name, k, size)
    fresh = refresh or set()
    if hit is not None and hit.classes is None:  # a cache from before the semantic term: classify again
        fresh = fresh | {SEMANTIC_EMBEDDER}
    cached = {e: hit.emb[e] for e in embedders if e in hit.emb and e not in fresh} if hit is not None else {}
    todo = [e for e in embedders if e not in cached]
    notes: list[str] = []
    if hit is not None and not hit.has_masks:  # mask embedders cannot use this video: no frames needed
        for e in list(todo):
            if needs_masks(cached_embedder(e, device)):
                notes.append(f"{e}: skipped, the query has no masks")
                todo.remove(e)
    if hit is not None and not todo and not need_images:
        masks = np.zeros((0, size, size), bool) if hit.has_masks else None
        query = QueryFrames(np.zeros((0, size, size, 3), np.uint8), masks, hit.frames, f"stored video {name}")
        query.notes = list(hit.notes)
        query.identities = {e: hit.identities[e] for e in cached if e in hit.identities}
        query.classes = hit.classes
        return query, cached, notes
    query = stored_query(videos, name, k, size)
    known = hit.emb if hit is not None else {}
    if hit is not None and not np.array_equal(hit.frames, query.frames):  # never mix two samplings
        known, cached, todo, notes = {}, {}, list(embedders), []
    new, new_notes = embed_query(query, todo, device)
    if query.classes is None and known and SEMANTIC_EMBEDDER not in new:
        query.classes = hit.classes
    idents = {**(hit.identities if known else {}), **query.identities}  # new embeddings, new identities
    query.identities = {e: idents[e] for e in (*cached, *new) if e in idents}
    if new:
        entry = query_cache.CachedQuery(
            query.frames, query.masks is not None, query.notes, {**known, **new}, idents, query.classes
        )
        query_cache.write_cache(videos, name, k, size, entry, identity)
    return (
        query,
        {e: cached[e] if e in cached else new[e] for e in embedders if e in cached or e in new},
        (notes + new_notes),
    )


def load_packs(
    bank,
    embedders: list[str],
    identities: dict[str, str] | None = None,
    entries: list[dict[str, Any]] | None = None,
) -> tuple[dict[str, Any], list[str]]:
    """The current pack of each embedder (one read of the bank index) and notes on missing views.
    ``identities``: the query's embedder identities, checked against the views' (`check_identities`);
    ``entries``: `Bank.list()` when the caller has read it."""
    entries = bank.list() if entries is None else entries
    packs = {}
    missing: dict[str, list[str]] = {}
    for e in embedders:
        check_identities(entries, e, (identities or {}).get(e))
        pack, missing[e] = current_pack(bank, e, entries)
        if pack is not None:
            packs[e] = pack
    notes = missing_views_notes(missing)
    if len(packs) < len(embedders):
        absent = sorted(set(embedders) - set(packs))
        raise UsageError(
            f"no asset in the bank has views for {', '.join(absent)}",
            hint="run `zooctl bank reindex` (or `bank add` assets)",
        )
    return packs, notes


def missing_views_notes(missing: dict[str, list[str]]) -> list[str]:
    """One note for the assets the search leaves out for want of views ({embedder: names}), named
    with the command that adds them; assets that lack only some embedders' views get one per embedder."""
    none = sorted(set.intersection(*(set(m) for m in missing.values()))) if missing else []
    notes = []
    if none:
        shown = ", ".join(none[:5]) + (f" and {len(none) - 5} more" if len(none) > 5 else "")
        # `reindex` embeds with the default embedders unless told otherwise
        default = set(missing) == set(enabled_embedders())
        flags = "" if default else "".join(f" --embedder {e}" for e in missing)
        what = "retrieval" if default else ", ".join(missing)
        notes.append(
            f"{len(none)} asset{'s' if len(none) > 1 else ''} without {what} views left out of the search: "
            f"{shown} (`zooctl bank reindex --missing{flags}` renders them)"
        )
    for e, m in missing.items():
        part = sorted(set(m) - set(none))
        if part:
            n = f"{len(part)} asset has" if len(part) == 1 else f"{len(part)} assets have"
            notes.append(f"{e}: {n} no views for it (run `zooctl bank reindex --embedder {e}`)")
    return notes


def score_packs(
    packs: dict[str, Any],
    query_emb: dict[str, np.ndarray],
    aggregation: str = "nearest",
    fusion: str = "zsum",
    k: int = 5,
    shortlist: int = DEFAULT_SHORTLIST,
    exclude: set[str] | None = None,
    weights: dict[str, float] | None = None,
    dist: np.ndarray | None = None,
    taxa: dict[str, Any] | None = None,
    semantic_weight: float | None = None,
    labels: dict[str, str] | None = None,
) -> SearchResult:
    """Rank the assets every pack holds (minus ``exclude``) for the query embeddings {embedder: (K, D)}.
    ``dist``: the query's (398,) animal-class distribution and ``taxa`` {asset: its label's `Taxon`
    or None} add the semantic term with ``semantic_weight`` (default `SEMANTIC_WEIGHT`; 0: off);
    ``labels``: {asset: its label as stored}, shown in the matches."""
    w_sem = SEMANTIC_WEIGHT if semantic_weight is None else float(semantic_weight)
    use_sem = dist is not None and taxa is not None and w_sem > 0

    first = packs[next(iter(query_emb))]
    common = set(first.names)
    for p in packs.values():
        if p is not first:
            common &= set(p.names)
    common -= exclude or set()
    if not common:
        raise UsageError("no asset has views for every chosen embedder", hint="run `zooctl bank reindex`")
    cand = sorted(common)
    if use_sem:  # relative to the best any candidate reaches, so a shortlist does not change it
        rel = dict(zip(cand, relative_scores(dist, semantic_scores(dist, [taxa.get(n) for n in cand]))))

    def sem_of(names: list[str]) -> np.ndarray:
        return np.array([rel[n] for n in names], np.float64)

    # Stage 1 (large banks): fused score of each asset's mean view embedding; keep the best.
    if len(cand) > shortlist:
        coarse = {}
        for e, p in packs.items():
            pos = p.positions()
            sims = query_emb[e].astype(np.float32) @ p.mean.T  # (K, A_e)
            rows = np.array([pos[n] for n in cand])
            coarse[e] = -sims.mean(0)[rows]
        rough = fuse(coarse, fusion, weights) - (w_sem * sem_of(cand) if use_sem else 0.0)
        top = np.argpartition(rough, shortlist - 1)[:shortlist]
        cand = sorted(cand[i] for i in top)
    # Stage 2: exact scores of the candidates: one (A*V, D) x (D, Q) float32 product per embedder.
    per_e: dict[str, np.ndarray] = {}
    views_best: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for e, p in packs.items():
        pos = p.positions()
        rows = np.array([pos[n] for n in cand])
        if len(rows) == len(p.names) and np.array_equal(rows, np.arange(len(rows))):
            emb = np.asarray(p.emb)
        elif np.all(np.diff(rows) > 0):  # packs are sorted by name, as cand is: read in file order
            emb = p.emb[rows]
        else:
            order = np.argsort(rows)
            emb = np.empty((len(rows), *p.emb.shape[1:]), np.float16)
            emb[order] = p.emb[rows[order]]
        A, V, D = emb.shape
        q = np.ascontiguousarray(query_emb[e], dtype=np.float32)  # (Q, D)
        if q.shape[1] != D:
            raise DimensionMismatch(e, D, q.shape[1])
        sim = (emb.reshape(A * V, D).astype(np.float32) @ q.T).reshape(A, V, -1)  # (A, V, Q)
        d = 1.0 - sim.transpose(0, 2, 1)  # (A, Q, V)
        valid = np.arange(V)[None, :] < p.counts[rows][:, None]  # (A, V): padding rows are inf
        d = np.where(valid[:, None, :], d, np.float32(np.inf))
        per_e[e] = aggregate(d, aggregation, k)
        views_best[e] = best_views(d)
    terms = fuse_terms(per_e, fusion, weights)
    sem = sem_of(cand) if use_sem else None
    q_taxon = query_taxon(dist) if use_sem else None
    if sem is not None:
        terms["semantic"] = -w_sem * sem
    total = sum_terms(terms)
    ranked = np.argsort(total, kind="stable")
    ranks = {e: np.argsort(np.argsort(s, kind="stable"), kind="stable") + 1 for e, s in per_e.items()}
    lead = next(iter(query_emb))
    matches = [
        Match(
            cand[i],
            float(total[i]),
            {e: float(s[i]) for e, s in per_e.items()},
            int(views_best[lead][0][i]),
            [int(x) for x in views_best[lead][1][i]],
            {e: float(t[i]) for e, t in terms.items()},
            {e: int(r[i]) for e, r in ranks.items()},
            (labels or {}).get(cand[i]),
            None if sem is None else float(sem[i]),
            _taxon_json(dist, taxa.get(cand[i]), q_taxon) if use_sem else None,
        )
        for i in ranked
    ]
    res = SearchResult(matches, list(query_emb), aggregation, fusion, len(cand))
    if use_sem:
        res.classes, res.semantic_weight = top_classes(dist), w_sem
    return res


def _taxon_json(dist: np.ndarray, taxon: Any, query: Any) -> list[str] | None:
    m = matched_taxon(dist, taxon, query)
    return None if m is None else list(m)


def score_bank(
    bank,
    query_emb: dict[str, np.ndarray],
    identities: dict[str, str] | None = None,
    classes: np.ndarray | None = None,
    **options: Any,
) -> SearchResult:
    """Rank every asset with views for all of ``query_emb``'s embedders. See the module docstring.
    ``identities``: the query's embedder identities (`QueryFrames.identities`); views of another
    version of an embedder are refused with `EmbedderMismatch`. ``classes``: the query's (K, 1000)
    ImageNet probabilities, for the semantic term (`zooctl.retrieval.semantic`)."""
    if not query_emb:
        raise UsageError(
            "no embedder could embed this query",
            hint="give masks for mask embedders, or choose another --embedder",
        )
    entries = bank.list()
    packs, notes = load_packs(bank, list(query_emb), identities, entries)
    labels = {e["name"]: e["label"] for e in entries if isinstance(e.get("label"), str)}
    options = {"labels": labels, **options}
    if classes is not None:
        taxa = {e["name"]: entry_taxon(e) for e in entries}
        options = {"dist": class_distribution(classes), "taxa": taxa, **options}
        if not any(t is not None for t in taxa.values()):
            notes.append("no asset in the bank has an animal label: `zooctl bank label NAME` infers one")
    res = score_packs(packs, query_emb, **options)
    res.notes = notes
    return res


def search(
    bank,
    query: QueryFrames,
    embedders: list[str],
    top: int = DEFAULT_TOP,
    device: str = "cpu",
    **options: Any,
) -> SearchResult:
    """Embed ``query`` and rank the bank; keeps the ``top`` best matches."""
    q, notes = embed_query(query, embedders, device)
    return search_embedded(bank, query, q, notes, top, **options)


def search_source(
    bank,
    source: Any,
    embedders: list[str],
    top: int = DEFAULT_TOP,
    frames: int = DEFAULT_QUERY_FRAMES,
    masks_dir: Any = None,
    store_root: Any = None,
    device: str = "cpu",
    need_images: bool = False,
    **options: Any,
) -> tuple[QueryFrames, SearchResult]:
    """`query_embeddings` then `search_embedded`, what `zooctl bank search` runs. A stored video's
    cached query embeddings from another version of an embedder than the bank's views (the
    embedder changed, and the bank was reindexed since) are embedded again once instead of failing."""
    kw = dict(k=frames, masks_dir=masks_dir, store_root=store_root, device=device, need_images=need_images)
    query, q, notes = query_embeddings(source, embedders, **kw)
    try:
        return query, search_embedded(bank, query, q, notes, top, **options)
    except EmbedderMismatch as exc:  # a cached query of an older embedder: embed it again (once)
        if _stored_video(source, masks_dir, store_root) is None:  # nothing was cached: the bank is stale
            raise
        query, q, notes = query_embeddings(source, embedders, refresh={exc.embedder}, **kw)
        return query, search_embedded(bank, query, q, notes, top, **options)


def search_embedded(
    bank,
    query: QueryFrames,
    q: dict[str, np.ndarray],
    notes: list[str],
    top: int = DEFAULT_TOP,
    **options: Any,
) -> SearchResult:
    """Rank the bank for query embeddings {embedder: (K, D)}; keeps the ``top`` best matches."""
    if top < 1:
        raise UsageError(f"--top {top} must be at least 1")
    res = score_bank(bank, q, query.identities, query.classes, **options)
    res.matches = res.matches[:top]
    res.notes = query.notes + notes + res.notes
    return res
