"""Retrieval views of bank assets: one sidecar HDF5 file per asset, plus a search pack per embedder.

Layout under the store root (JSON Schema: ``schemas/asset_views.schema.json``)::

    bank/views/<name>.h5            the asset's rendered views (written on `bank add` / `bank reindex`)
        attrs: zooctl_kind="asset_views", schema_version, asset, views_id, asset_digest,
               seed, size, count, created
        /images                     (V,) variable-length uint8: JPEG bytes of each view crop
        /masks                      (V, S, S) bool: the silhouette of each crop (lzf)
        /params/<key>               (V,) or (V, 3): clip index, frame, azimuth, elevation, fov,
                                    ambient, light; /params attrs: clip_names (JSON)
        /embeddings/<embedder>      (V, D) float16 unit-norm rows; attrs: dim, input_kind
    bank/views/pack-<embedder>.json {"files": {"emb", "mean"}, "names": [...], "counts": [...],
                                    "views_ids": {name: views_id}} - names the two files below
    bank/views/pack-<embedder>-<id>.npy       (A, Vmax, D) float16: every asset's view embeddings,
                                              rows past an asset's count are zero
    bank/views/pack-<embedder>-<id>.mean.npy  (A, D) float32: each asset's mean view embedding
    (packs are caches rebuilt from the sidecars when the index names other views_ids)

Why a sidecar rather than groups inside the asset file: writing views never rewrites (or races
with a writer of) the asset file, and it is cheap to read the views of many assets without
touching meshes and clips. The bank index entry of an asset carries ``views`` (count, size,
embedder dims and ``views_id``) once its sidecar is published; `Bank.add` rewrites the entry, so a
re-added asset has no views until they are rendered again, and a sidecar whose ``views_id`` the
index does not name is ignored. Each file is written to a temporary beside it and published with
``os.replace`` under the store's writers' lock; packs are caches that any reader may rebuild.
"""

from __future__ import annotations

import hashlib
import json
import re
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from ..errors import NoSpaceError, ReadOnlyStoreError, StoreError
from .fs import h5_image, publish, read_regular, store_lock, temp_path, writing
from .h5 import read_h5

SCHEMA_VERSION = 1
JPEG_QUALITY = 90


def views_dir(root: Path) -> Path:
    return Path(root) / "bank" / "views"


def views_path(root: Path, name: str) -> Path:
    return views_dir(root) / f"{name}.h5"


def unreferenced_files(root: Path, names: set[str]) -> list[Path]:
    """Files under ``bank/views/`` nothing refers to: sidecars of assets not in ``names`` (the bank
    index) and pack data files that no pack JSON names. Call under the store lock; temporaries are
    `fs.remove_stale_temps`'s business."""
    d = views_dir(root)
    if not d.is_dir():
        return []
    named: set[str] = set()
    for meta_p in d.glob("pack-*.json"):
        try:
            named.update(json.loads(read_regular(meta_p)).get("files", {}).values())
        except (OSError, ValueError, AttributeError):
            pass  # an unreadable pack is a cache: its data files go, and search rebuilds it
    out = []
    for p in sorted(d.iterdir()):
        if p.name.startswith(".") or not p.is_file():
            continue
        if (p.suffix == ".h5" and p.stem not in names) or (
            p.name.startswith("pack-") and p.suffix == ".npy" and p.name not in named
        ):
            out.append(p)
    return out


def summary_digest(summary: dict[str, Any]) -> str:
    """A digest of an asset's index entry without its ``views`` (and whether they are pending) and
    animal label (relabelling keeps the views): changes when the asset is re-added."""
    s = {k: v for k, v in summary.items() if k not in ("views", "views_pending", "label", "label_source")}
    return hashlib.sha256(json.dumps(s, sort_keys=True, default=str).encode()).hexdigest()[:16]


@dataclass
class StoredViews:
    """What a sidecar holds. images (V, S, S, 3) uint8 (None unless asked for), masks (V, S, S) bool,
    embeddings {embedder: (V, D) float32} and their input_kinds {embedder: "rgb", "mask" or "rgb+mask"},
    params {key: (V,...) array}."""

    asset: str
    views_id: str
    asset_digest: str
    size: int
    count: int
    seed: int
    embeddings: dict[str, np.ndarray] = field(default_factory=dict)
    input_kinds: dict[str, str] = field(default_factory=dict)
    masks: np.ndarray | None = None
    images: np.ndarray | None = None
    params: dict[str, np.ndarray] = field(default_factory=dict)
    clip_names: list[str] = field(default_factory=list)


def encode_jpeg(image: np.ndarray) -> np.ndarray:
    import cv2

    ok, buf = cv2.imencode(
        ".jpg", np.ascontiguousarray(image[..., ::-1]), [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY]
    )
    if not ok:  # pragma: no cover - OpenCV fails only on empty images
        raise StoreError("could not encode a view as JPEG")
    return buf.reshape(-1)


def decode_jpeg(data: np.ndarray) -> np.ndarray:
    import cv2

    img = cv2.imdecode(np.asarray(data, np.uint8), cv2.IMREAD_COLOR)
    if img is None:
        raise StoreError(
            "a stored view is not a readable JPEG", hint="run `zooctl bank reindex` for the asset"
        )
    return img[..., ::-1].copy()


def write_views(
    root: Path,
    name: str,
    viewset: Any,
    embeddings: dict[str, np.ndarray],
    asset_digest: str,
    input_kinds: dict[str, str] | None = None,
) -> str:
    """Publish the sidecar of asset ``name`` atomically (temporary + fsync + replace, under the lock).

    ``viewset`` is a `zooctl.retrieval.views.ViewSet`; ``embeddings`` maps embedder name to (V, D).
    Returns the new ``views_id``.
    """
    final = views_path(root, name)
    views_id = uuid.uuid4().hex[:16]
    V = len(viewset)

    def fill(f: h5py.File) -> None:
        f.attrs.update(
            zooctl_kind="asset_views",
            schema_version=SCHEMA_VERSION,
            asset=name,
            views_id=views_id,
            asset_digest=asset_digest,
            seed=int(viewset.seed),
            size=int(viewset.images.shape[1]),
            count=V,
            created=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        )
        jpegs = f.create_dataset("images", (V,), dtype=h5py.vlen_dtype(np.uint8))
        for i, im in enumerate(viewset.images):
            jpegs[i] = encode_jpeg(im)
        f.create_dataset(
            "masks",
            data=viewset.masks.astype(bool),
            compression="lzf",
            chunks=(1, *viewset.masks.shape[1:]),
        )
        p = f.create_group("params")
        p.attrs["clip_names"] = json.dumps(list(viewset.clip_names))
        for key, arr in viewset.params.items():
            p.create_dataset(key, data=np.asarray(arr))
        e = f.create_group("embeddings")
        for emb_name, arr in embeddings.items():
            arr = np.asarray(arr, np.float32)
            if arr.shape[0] != V:
                raise StoreError(f"embedder {emb_name!r} returned {arr.shape[0]} rows for {V} views")
            d = e.create_dataset(emb_name, data=arr.astype(np.float16))
            d.attrs["dim"] = int(arr.shape[1])
            d.attrs["input_kind"] = (input_kinds or {}).get(emb_name, "rgb")

    # Built in memory: a full disk is then a clean error from write(), not one inside HDF5.
    image = h5_image(fill, libver="latest")
    tmp = temp_path(final)
    try:
        with writing(f"writing the views of {name!r}"):
            tmp.write_bytes(image)
            with store_lock(Path(root)):
                publish(tmp, final)
    finally:
        tmp.unlink(missing_ok=True)
    return views_id


def read_views(
    path: Path,
    images: bool = False,
    masks: bool = False,
    embedders: list[str] | None = None,
    rows: np.ndarray | None = None,
) -> StoredViews:
    """Read a sidecar. ``images``/``masks`` load those arrays; ``embedders`` limits the embeddings
    read (None: all); ``rows`` limits images and masks to those view indices."""
    return read_h5(
        path,
        "views file",
        "run `zooctl bank reindex`",
        lambda f: _read_views(f, path, images, masks, embedders, rows),
    )


def _read_views(
    f: h5py.File, path: Path, images: bool, masks: bool, embedders: list[str] | None, rows: np.ndarray | None
) -> StoredViews:
    a = f.attrs
    if a.get("zooctl_kind") != "asset_views":
        raise StoreError(f"{path} is not a zooctl views file")
    v = int(a.get("schema_version", 0))
    if v != SCHEMA_VERSION:
        raise StoreError(
            f"{path} has views layout {v}, this zooctl reads {SCHEMA_VERSION}",
            hint="run `zooctl bank reindex`",
        )
    out = StoredViews(
        str(a["asset"]),
        str(a["views_id"]),
        str(a["asset_digest"]),
        int(a["size"]),
        int(a["count"]),
        int(a["seed"]),
    )
    names = list(f["embeddings"]) if embedders is None else [e for e in embedders if e in f["embeddings"]]
    out.embeddings = {e: f["embeddings"][e][()].astype(np.float32) for e in names}
    out.input_kinds = {e: str(f["embeddings"][e].attrs.get("input_kind", "rgb")) for e in names}
    idx = np.arange(out.count) if rows is None else np.asarray(rows, dtype=np.int64)
    if masks:
        out.masks = (
            np.stack([f["masks"][int(i)] for i in idx])
            if len(idx)
            else np.zeros((0, out.size, out.size), bool)
        )
    if images:
        out.images = (
            np.stack([decode_jpeg(f["images"][int(i)]) for i in idx])
            if len(idx)
            else np.zeros((0, out.size, out.size, 3), np.uint8)
        )
    out.params = {k: f["params"][k][()] for k in f["params"]}
    out.clip_names = json.loads(f["params"].attrs.get("clip_names", "[]"))
    return out


# -- search packs ------------------------------------------------------------------------------------


@dataclass
class Pack:
    """Every asset's view embeddings for one embedder.

    names (A,); counts (A,) views per asset; emb (A, Vmax, D) float16 (rows past counts are zero,
    memory-mapped from disk); mean (A, D) float32: each asset's mean view embedding.
    """

    embedder: str
    names: list[str]
    counts: np.ndarray
    emb: np.ndarray
    mean: np.ndarray
    views_ids: dict[str, str]
    _positions: dict[str, int] | None = None

    def positions(self) -> dict[str, int]:
        """{name: row} (cached: searches look names up twice per embedder)."""
        if self._positions is None:
            self._positions = {n: i for i, n in enumerate(self.names)}
        return self._positions


_PACK_FILE = re.compile(r"pack-[A-Za-z0-9_.\-]+\.npy")


def _pack_meta_path(root: Path, embedder: str) -> Path:
    return views_dir(root) / f"pack-{embedder}.json"


def read_pack(root: Path, embedder: str) -> Pack | None:
    """The pack on disk, or None when there is none (or it is unreadable: it is only a cache)."""
    d = views_dir(root)
    try:
        meta = json.loads(read_regular(_pack_meta_path(root, embedder)))
        if meta.get("schema_version") != SCHEMA_VERSION:
            return None
        if not all(_PACK_FILE.fullmatch(str(f)) and (d / f).is_file() for f in meta["files"].values()):
            return None  # is_file: a FIFO in its place would block np.load
        emb = np.load(d / meta["files"]["emb"], mmap_mode="r")
        mean = np.load(d / meta["files"]["mean"], mmap_mode="r")
        names, counts, ids = (
            list(meta["names"]),
            np.asarray(meta["counts"], np.int64),
            dict(meta["views_ids"]),
        )
        if emb.ndim != 3 or mean.ndim != 2 or not emb.shape[0] == mean.shape[0] == len(names) == len(counts):
            return None
    except (OSError, ValueError, KeyError, TypeError, AttributeError, EOFError):  # only a cache: rebuilt
        return None
    return Pack(embedder, names, counts, emb, mean, ids)


def write_pack(
    root: Path,
    embedder: str,
    names: list[str],
    counts: np.ndarray,
    emb: np.ndarray,
    views_ids: dict[str, str],
) -> Pack:
    """Publish a pack under the lock: its data files under fresh names first, then the JSON that
    names them (the atomic switch), then remove the previous data files."""
    d = views_dir(root)
    meta_p = _pack_meta_path(root, embedder)
    counts = np.asarray(counts, np.int64)
    emb = np.asarray(emb, np.float16)
    mean = emb.astype(np.float32).sum(1) / np.maximum(counts, 1)[:, None]
    pid = uuid.uuid4().hex[:12]
    files = {"emb": f"pack-{embedder}-{pid}.npy", "mean": f"pack-{embedder}-{pid}.mean.npy"}
    meta = {
        "schema_version": SCHEMA_VERSION,
        "embedder": embedder,
        "files": files,
        "names": list(names),
        "counts": counts.tolist(),
        "views_ids": views_ids,
    }
    try:
        _publish_pack(d, meta_p, files, meta, emb, mean)
    except (ReadOnlyStoreError, NoSpaceError):
        # A pack is only a cache: on a read-only or full store, search with the one built here.
        return Pack(embedder, list(names), counts, emb, mean.astype(np.float32), dict(views_ids))
    return read_pack(root, embedder) or Pack(embedder, list(names), counts, emb, mean, views_ids)


def _publish_pack(d: Path, meta_p: Path, files: dict, meta: dict, emb: np.ndarray, mean: np.ndarray) -> None:
    root = d.parent.parent
    finals = [d / files["emb"], d / files["mean"], meta_p]
    tmps: list[Path] = []
    try:
        tmps += [temp_path(p) for p in finals]
        with writing("writing a search pack"):
            with open(tmps[0], "wb") as fh:
                np.save(fh, emb)
            with open(tmps[1], "wb") as fh:
                np.save(fh, mean.astype(np.float32))
            tmps[2].write_text(json.dumps(meta))
        with store_lock(Path(root)), writing("publishing a search pack"):
            try:
                old = list(json.loads(read_regular(meta_p)).get("files", {}).values())
            except (OSError, ValueError, AttributeError, TypeError):
                old = []
            for t, p in zip(tmps, finals):
                publish(t, p)
            for f in old:  # a damaged pack file must not name anything else to delete
                if isinstance(f, str) and _PACK_FILE.fullmatch(f) and f not in files.values():
                    (d / f).unlink(missing_ok=True)
    finally:
        for t in tmps:
            t.unlink(missing_ok=True)
