"""Index bank assets for retrieval: render views, embed them with every enabled embedder, store.

``index_asset`` is what `bank add` (``views=True``) and `bank reindex` call; ``current_pack`` gives
search one (A, Vmax, D) matrix per embedder, rebuilt from the sidecars only when the bank index
names views the pack does not hold (`zooctl.store.views_h5`).
"""

from __future__ import annotations

import os
import zlib
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..embed.base import DEFAULT_EMBEDDERS, Embedder, embedder_identity
from ..errors import StoreError, UsageError
from ..store import views_h5
from .embedder_cache import cached_embedder
from .views import DEFAULT_SIZE, DEFAULT_VIEWS, ViewSet, render_views


def enabled_embedders() -> list[str]:
    """Embedders whose view embeddings `bank add` stores: ZOOCTL_EMBEDDERS (comma list) or the defaults."""
    v = os.environ.get("ZOOCTL_EMBEDDERS")
    names = [s.strip() for s in v.split(",") if s.strip()] if v is not None else list(DEFAULT_EMBEDDERS)
    return list(dict.fromkeys(names))


MASK_KINDS = ("mask", "rgb+mask")


def needs_masks(embedder: Embedder) -> bool:
    """Whether the embedder reads masks (``input_kind`` "mask" or "rgb+mask")."""
    return getattr(embedder, "input_kind", "rgb") in MASK_KINDS


def embed_inputs(embedder: Embedder, images: np.ndarray, masks: np.ndarray | None) -> np.ndarray:
    """Run an embedder on what it takes: RGB crops (N, S, S, 3), masks (N, S, S), or both."""
    if needs_masks(embedder):
        if masks is None:
            raise UsageError(
                f"the {embedder.name!r} embedder needs masks of the animal",
                hint="give masks (--masks) or choose another --embedder",
            )
        if embedder.input_kind == "rgb+mask":
            return embedder.embed_batch(images, masks)
        return embedder.embed_batch(masks)
    return embedder.embed_batch(images)


def view_seed(name: str, seed: int = 0) -> int:
    """A per-asset seed: the same asset name always gets the same views."""
    return (zlib.crc32(name.encode()) + 7919 * seed) & 0x7FFFFFFF


def index_asset(
    bank,
    asset,
    embedders: Iterable[str] | None = None,
    n_views: int = DEFAULT_VIEWS,
    size: int = DEFAULT_SIZE,
    seed: int = 0,
    device: str = "cpu",
) -> dict[str, Any]:
    """Render, embed and store the retrieval views of ``asset`` (already in ``bank``).

    The asset's other embedders' embeddings are kept: where its stored views are the ones this
    call renders (same asset, count, size and seed; renders are deterministic) they are copied,
    otherwise those embedders embed the new views too. So `bank reindex --embedder clip` adds or
    refreshes clip without dropping effnet. Returns the ``views`` entry recorded in the bank index:
    count, size, embedder dims and identities (`embedder_identity`), views_id.
    """
    names = list(embedders) if embedders is not None else enabled_embedders()
    summary = bank.summary(asset.name)
    digest = views_h5.summary_digest(summary)
    computed = compute_views(bank, asset, summary, names, n_views, size, seed, device)
    return store_views(bank, asset.name, computed, digest)


@dataclass
class ComputedViews:
    """An asset's rendered views and their embeddings, not stored yet (what a batch worker returns)."""

    views: ViewSet
    embeddings: dict[str, np.ndarray]
    kinds: dict[str, str]
    identities: dict[str, str]
    size: int
    classes: np.ndarray | None = None  # (1000,) mean ImageNet probabilities of the views (effnet)


def compute_views(
    bank,
    asset,
    summary: dict[str, Any] | None,
    names: list[str],
    n_views: int = DEFAULT_VIEWS,
    size: int = DEFAULT_SIZE,
    seed: int = 0,
    device: str = "cpu",
) -> ComputedViews:
    """Render and embed; only reads ``bank`` (the asset's current views, to keep its other
    embedders' embeddings: ``summary`` is its index entry, None for an asset not stored yet)."""
    vs: ViewSet = render_views(
        asset, n_views=n_views, size=size, seed=view_seed(asset.name, seed), device=device
    )
    embs, kinds, idents = {}, {}, {}
    old = summary.get("views") if summary and isinstance(summary.get("views"), dict) else {}
    others = [e for e in old.get("embedders", {}) if e not in names]
    kept = (
        _stored_embeddings(bank, asset.name, old, others, views_h5.summary_digest(summary), vs)
        if summary
        else {}
    )
    for e, (arr, kind, ident) in kept.items():
        embs[e], kinds[e] = arr, kind
        if ident:
            idents[e] = ident
    classes = None
    for e in names + [e for e in others if e not in kept]:
        emb = cached_embedder(e, device)
        if e == "effnet" and hasattr(emb, "embed_and_classify"):  # one pass: views and their classes
            embs[e], probs = emb.embed_and_classify(vs.images)
            classes = probs.mean(0)
        else:
            embs[e] = embed_inputs(emb, vs.images, vs.masks)
        kinds[e] = getattr(emb, "input_kind", "rgb")
        idents[e] = embedder_identity(emb)
    return ComputedViews(vs, embs, kinds, idents, size, classes)


def store_views(bank, name: str, cv: ComputedViews, digest: str | None = None) -> dict[str, Any]:
    """Write the views sidecar and the index entry. ``digest``: the asset's summary digest the
    views were made for (None: the asset as stored now); a replaced asset is refused."""
    digest = digest if digest is not None else views_h5.summary_digest(bank.summary(name))
    views_id = views_h5.write_views(bank.root, name, cv.views, cv.embeddings, digest, cv.kinds)
    if views_h5.summary_digest(bank.summary(name)) != digest:
        raise StoreError(
            f"asset {name!r} was replaced while its views were rendered",
            hint=f"run `zooctl bank reindex {name}`",
        )
    entry = {
        "count": len(cv.views),
        "size": cv.size,
        "embedders": {e: int(a.shape[1]) for e, a in cv.embeddings.items()},
        "identities": cv.identities,
        "views_id": views_id,
    }
    bank.update_summary(name, views=entry)
    from .labels import label_from_views

    label_from_views(bank, name, cv.classes)  # unlabelled (added before labels): name, tags or views
    return entry


def _stored_embeddings(
    bank, name: str, entry: dict[str, Any], embedders: list[str], digest: str, vs: ViewSet
) -> dict[str, tuple[np.ndarray, str, str | None]]:
    """{embedder: (V, D) embeddings, input kind, identity} of the asset's current sidecar, for
    those of ``embedders`` it holds, when its views are the ones ``vs`` renders again."""
    if not embedders or not entry.get("views_id"):
        return {}
    try:
        sv = views_h5.read_views(views_h5.views_path(bank.root, name), embedders=embedders)
    except StoreError:
        return {}
    same = (
        sv.views_id == entry["views_id"]
        and sv.asset_digest == digest
        and (sv.count, sv.size, sv.seed) == (len(vs), vs.images.shape[1], vs.seed)
    )
    if not same:
        return {}
    idents = entry.get("identities", {})
    return {e: (a, sv.input_kinds.get(e, "rgb"), idents.get(e)) for e, a in sv.embeddings.items()}


def views_entries(bank, summaries: list[dict[str, Any]] | None = None) -> dict[str, dict[str, Any]]:
    """{asset name: its index ``views`` entry} for every asset that has views (``summaries``: a
    `Bank.list()` already read)."""
    rows = bank.list() if summaries is None else summaries
    return {s["name"]: s["views"] for s in rows if isinstance(s.get("views"), dict)}


def current_pack(
    bank, embedder: str, summaries: list[dict[str, Any]] | None = None
) -> tuple[views_h5.Pack | None, list[str]]:
    """The search pack of ``embedder`` for the bank as it is now, and the assets left out of it
    (no views, or none for this embedder). Rebuilds the pack from sidecars when it is stale.
    ``summaries``: `Bank.list()` when the caller has read it already (it is the slow part)."""
    summaries = bank.list() if summaries is None else summaries
    entries = views_entries(bank, summaries)
    wanted = {n: e["views_id"] for n, e in entries.items() if embedder in e.get("embedders", {})}
    missing = sorted({s["name"] for s in summaries} - set(wanted))
    pack = views_h5.read_pack(bank.root, embedder)
    if pack is not None and pack.views_ids == wanted:
        return pack, missing
    if not wanted:
        return None, missing
    old_rows = {n: i for i, n in enumerate(pack.names)} if pack is not None else {}
    names, rows, counts, ids = [], [], [], {}
    for n in sorted(wanted):
        if pack is not None and pack.views_ids.get(n) == wanted[n]:
            i = old_rows[n]
            rows.append(np.asarray(pack.emb[i, : pack.counts[i]], np.float16))
        else:
            try:
                sv = views_h5.read_views(views_h5.views_path(bank.root, n), embedders=[embedder])
            except StoreError:
                missing.append(n)
                continue
            if sv.views_id != wanted[n] or embedder not in sv.embeddings:  # being rewritten right now
                missing.append(n)
                continue
            rows.append(sv.embeddings[embedder].astype(np.float16))
        names.append(n)
        counts.append(len(rows[-1]))
        ids[n] = wanted[n]
    if not names:
        return None, sorted(missing)
    D = rows[0].shape[1]
    emb = np.zeros((len(names), max(counts), D), np.float16)
    for i, r in enumerate(rows):
        emb[i, : len(r)] = r
    return views_h5.write_pack(bank.root, embedder, names, np.array(counts), emb, ids), sorted(missing)
