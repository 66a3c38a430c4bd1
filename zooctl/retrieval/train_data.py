"""Training data for the retrieval embedder: views of random procedural animals, as frozen features.

Every animal (`zooctl.procedural.random.random_assets`) is rendered exactly like a bank asset's
retrieval views (`zooctl.retrieval.views.render_views`: random clip frames plus joint
perturbations, cameras, lights, backgrounds, square crops), then each view is reduced to the
frozen features the trained head reads: EfficientNet-Lite0's pooled 1280-d features of the RGB
crop and the 576-d silhouette descriptor of its mask. Only features are kept (images are not
needed to train the head), cached as one ``.npz`` per (animals, views, seed, backbone identity).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..embed.base import embedder_identity
from .index import cached_embedder, view_seed
from .views import DEFAULT_SIZE, render_views

FEATURES = ("effnet", "silhouette")


@dataclass
class TrainingSet:
    """Frozen features of M = animals x views rendered views.

    features: {name: (M, D) float32}; label (M,) int index into ``labels``; animal (M,) int.
    """

    features: dict[str, np.ndarray]
    label: np.ndarray
    animal: np.ndarray
    labels: list[str]

    def __len__(self) -> int:
        return int(self.label.shape[0])


def feature_identity(device: str = "cpu") -> str:
    """The identities of the frozen feature extractors, joined (part of the cache key)."""
    return "+".join(embedder_identity(cached_embedder(f, device)) for f in FEATURES)


def render_training_set(
    n_animals: int, n_views: int, seed: int = 0, size: int = DEFAULT_SIZE, device: str = "cpu", progress=None
) -> TrainingSet:
    """Render ``n_animals`` random animals (all body plans in turn) x ``n_views`` views and embed them."""
    from ..procedural.random import LABELS, random_assets

    labels = list(LABELS)
    feats: dict[str, list[np.ndarray]] = {f: [] for f in FEATURES}
    lab, ani = [], []
    embedders = {f: cached_embedder(f, device) for f in FEATURES}
    for i in range(n_animals):
        (asset,) = random_assets(1, seed=seed, labels=[labels[i % len(labels)]], start=i)
        vs = render_views(asset, n_views=n_views, size=size, seed=view_seed(asset.name, seed), device=device)
        feats["effnet"].append(embedders["effnet"].embed_batch(vs.images))
        feats["silhouette"].append(embedders["silhouette"].embed_batch(vs.masks))
        lab.append(np.full(n_views, labels.index(asset.meta["body_plan"])))
        ani.append(np.full(n_views, i))
        if progress is not None:
            progress(i + 1, n_animals)
    return TrainingSet(
        {f: np.concatenate(v).astype(np.float32) for f, v in feats.items()},
        np.concatenate(lab).astype(np.int64),
        np.concatenate(ani).astype(np.int64),
        labels,
    )


def cache_path(cache_dir: Path, n_animals: int, n_views: int, seed: int, size: int, device: str) -> Path:
    import hashlib

    key = f"{n_animals}/{n_views}/{seed}/{size}/{feature_identity(device)}"
    return Path(cache_dir) / f"procedural-{hashlib.sha256(key.encode()).hexdigest()[:16]}.npz"


def load_or_render(cache_dir: Path | None, *args, **kwargs) -> TrainingSet:
    """`render_training_set(*args, **kwargs)`, read from / written to ``cache_dir`` when given
    (atomic write). ``progress(i, n)`` is called after each animal rendered."""
    import inspect
    import os

    a = inspect.signature(render_training_set).bind(*args, **kwargs)
    a.apply_defaults()
    k = a.arguments
    path = (
        cache_path(cache_dir, k["n_animals"], k["n_views"], k["seed"], k["size"], k["device"])
        if cache_dir
        else None
    )
    if path is not None and path.exists():
        z = np.load(path)
        return TrainingSet(
            {f: z[f] for f in FEATURES}, z["label"], z["animal"], [str(s) for s in z["labels"]]
        )
    ts = render_training_set(*args, **kwargs)
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".tmp{os.getpid()}.npz")
        np.savez(
            tmp,
            label=ts.label,
            animal=ts.animal,
            labels=np.array(ts.labels),
            **{f: ts.features[f].astype(np.float16) for f in FEATURES},
        )
        os.replace(tmp, path)
    return ts
