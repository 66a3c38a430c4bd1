"""Query embeddings of stored videos, cached beside the video so a repeated `bank search` of the
same video skips decoding, cropping, loading the embedders and importing torch.

One file per sampling, ``videos/<name>.cache/query-k<K>-s<S>.npz`` (`VideoStore.cache_dir`, removed
with the video): ``frames`` (K,) int64 chosen frame indices, ``emb/<embedder>`` (K, D) float32 per
embedder, ``classes`` (K, 1000) float32 ImageNet probabilities of the crops when effnet embedded
them (`zooctl.retrieval.semantic`; absent in older caches), and ``meta`` (JSON): cache version, the video file's identity (inode, size, mtime: a
re-added video is a new file), whether the crops had masks, the query notes, each embedder's
identity (`zooctl.embed.base.embedder_identity`, so a search can tell embeddings of an older
version of an embedder from the bank's). Anything unreadable or not matching is a miss, never an
error: the cache is rebuilt from the video. On a read-only or full store it is not written.
"""

from __future__ import annotations

import io
import json
import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import NoSpaceError, ReadOnlyStoreError
from ..store.fs import store_lock, write_bytes_atomic
from .crop import DEFAULT_MARGIN

CACHE_VERSION = 2  # 2: classes of the crops kept within the frame (`zooctl.retrieval.query.classifier_crops`)


@dataclass
class CachedQuery:
    """What a search needs of a query without its pixels: frames (K,), has_masks, notes,
    emb {embedder: (K, D) float32} and identities {embedder: identity} (absent in older caches)."""

    frames: np.ndarray
    has_masks: bool
    notes: list[str]
    emb: dict[str, np.ndarray] = field(default_factory=dict)
    identities: dict[str, str] = field(default_factory=dict)
    classes: np.ndarray | None = None


def cache_path(videos, name: str, k: int, size: int) -> Path:
    return videos.cache_dir(name) / f"query-k{k}-s{size}.npz"


def video_identity(videos, name: str) -> list[int] | None:
    """(inode, bytes, mtime ns) of the stored video file, or None when it is missing."""
    try:
        st = os.stat(videos.path(name))
    except OSError:
        return None
    return [int(st.st_ino), int(st.st_size), int(st.st_mtime_ns)]


def _expected_meta(videos, name: str) -> dict:
    return {"version": CACHE_VERSION, "margin": DEFAULT_MARGIN, "video": video_identity(videos, name)}


def read_cache(videos, name: str, k: int, size: int) -> CachedQuery | None:
    """The cached query of ``name`` at this sampling, or None (absent, stale or unreadable)."""
    path = cache_path(videos, name, k, size)
    if not path.is_file():  # absent, or a FIFO or device (np.load would block on it)
        return None
    try:
        with np.load(path, allow_pickle=False) as z:
            meta = json.loads(str(z["meta"]))
            if {key: meta.get(key) for key in ("version", "margin", "video")} != _expected_meta(videos, name):
                return None
            emb = {
                key[len("emb/") :]: np.asarray(z[key], np.float32)
                for key in z.files
                if key.startswith("emb/")
            }
            frames = np.asarray(z["frames"], np.int64)
            classes = np.asarray(z["classes"], np.float32) if "classes" in z.files else None
    except (OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile):  # damaged: a miss
        return None
    if frames.ndim != 1 or any(e.ndim != 2 or len(e) != len(frames) for e in emb.values()):
        return None
    if classes is not None and (classes.ndim != 2 or len(classes) != len(frames)):
        classes = None
    idents = meta.get("identities") if isinstance(meta.get("identities"), dict) else {}
    return CachedQuery(
        frames,
        bool(meta.get("has_masks")),
        [str(n) for n in meta.get("notes", [])],
        emb,
        {str(k): str(v) for k, v in idents.items() if k in emb},
        classes,
    )


def write_cache(videos, name: str, k: int, size: int, query: CachedQuery, identity: list[int] | None) -> None:
    """Store ``query`` atomically under the store lock. ``identity``: `video_identity` taken before
    the video was read (a video replaced meanwhile leaves a cache that never matches)."""
    if identity is None:
        return
    meta = {
        "version": CACHE_VERSION,
        "margin": DEFAULT_MARGIN,
        "video": identity,
        "has_masks": query.has_masks,
        "notes": query.notes,
        "identities": query.identities,
    }
    buf = io.BytesIO()
    np.savez(
        buf,
        meta=np.array(json.dumps(meta)),
        frames=np.asarray(query.frames, np.int64),
        **{f"emb/{e}": np.asarray(v, np.float32) for e, v in query.emb.items()},
        **({} if query.classes is None else {"classes": np.asarray(query.classes, np.float32)}),
    )
    final = cache_path(videos, name, k, size)
    try:
        with store_lock(Path(videos.root)):
            if video_identity(videos, name) != identity:  # removed or replaced while we embedded
                return
            write_bytes_atomic(final, buf.getvalue())
    except (ReadOnlyStoreError, NoSpaceError):
        return  # a cache: a search on a read-only or full store works without it
