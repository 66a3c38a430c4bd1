"""Training data for the retrieval embedder: views of random procedural animals, as frozen features.

Every animal (`zooctl.procedural.random.random_assets`) is rendered exactly like a bank asset's
retrieval views (`zooctl.retrieval.views.render_views`: random clip frames plus joint
perturbations, cameras, lights, backgrounds, square crops), then each view is reduced to the
frozen features the trained head reads: EfficientNet-Lite0's pooled 1280-d features of the RGB
crop and the 576-d silhouette descriptor of its mask. Only features are kept (images are not
needed to train the head), cached as one ``.npz`` per (animals, views, seed, backbone identity,
generator and view-rendering source digests).
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


def unweld(asset):
    """The asset with every face on its own three vertices: flat-shaded facets, as low-poly
    artist meshes look, instead of smooth normals."""
    import dataclasses

    idx = asset.faces.reshape(-1)
    cols = None if asset.vertex_colors is None else asset.vertex_colors[idx]
    return dataclasses.replace(
        asset,
        vertices=asset.vertices[idx],
        faces=np.arange(len(idx), dtype=np.int32).reshape(-1, 3),
        skin_joints=asset.skin_joints[idx],
        skin_weights=asset.skin_weights[idx],
        vertex_colors=cols,
        uvs=None if asset.uvs is None else asset.uvs[idx],
    )


def randomize_look(asset, rng: np.random.Generator):
    """Domain randomisation of one training animal: flat facets half of the time, and per-vertex
    colour noise of a random strength (mottled texture)."""
    import dataclasses

    if rng.random() < 0.5:
        asset = unweld(asset)
    if asset.vertex_colors is not None:
        noise = rng.normal(0, rng.uniform(0, 0.08), asset.vertex_colors.shape).astype(np.float32)
        asset = dataclasses.replace(asset, vertex_colors=np.clip(asset.vertex_colors + noise, 0, 1))
    return asset


def render_training_set(
    n_animals: int,
    n_views: int,
    seed: int = 0,
    size: int = DEFAULT_SIZE,
    device: str = "cpu",
    progress=None,
    randomize: bool = False,
) -> TrainingSet:
    """Render ``n_animals`` random animals (all body plans in turn) x ``n_views`` views and embed them.
    ``randomize``: any hue (`zooctl.procedural.palette`) and `randomize_look` for every animal."""
    from ..procedural.random import LABELS, random_assets

    labels = list(LABELS)
    feats: dict[str, list[np.ndarray]] = {f: [] for f in FEATURES}
    lab, ani = [], []
    embedders = {f: cached_embedder(f, device) for f in FEATURES}
    for i in range(n_animals):
        (asset,) = random_assets(1, seed=seed, labels=[labels[i % len(labels)]], start=i, any_hue=randomize)
        if randomize:
            asset = randomize_look(asset, np.random.default_rng([seed, i, 7]))
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


def cache_path(
    cache_dir: Path, n_animals: int, n_views: int, seed: int, size: int, device: str, randomize: bool = False
) -> Path:
    import hashlib

    from ..procedural.random import generator_identity
    from . import views

    render = hashlib.sha256(Path(views.__file__).read_bytes()).hexdigest()[:16]
    key = f"{n_animals}/{n_views}/{seed}/{size}/{feature_identity(device)}/{generator_identity()}/{render}"
    if randomize:
        key += "/randomized"
    return Path(cache_dir) / f"procedural-{hashlib.sha256(key.encode()).hexdigest()[:16]}.npz"


def read_cached(path: Path) -> TrainingSet:
    """A training set written by `load_or_render`."""
    z = np.load(path)
    return TrainingSet({f: z[f] for f in FEATURES}, z["label"], z["animal"], [str(s) for s in z["labels"]])


def load_or_render(cache_dir: Path | None, *args, **kwargs) -> TrainingSet:
    """`render_training_set(*args, **kwargs)`, read from / written to ``cache_dir`` when given
    (atomic write). ``progress(i, n)`` is called after each animal rendered."""
    import inspect
    import os

    a = inspect.signature(render_training_set).bind(*args, **kwargs)
    a.apply_defaults()
    k = a.arguments
    path = (
        cache_path(cache_dir, k["n_animals"], k["n_views"], k["seed"], k["size"], k["device"], k["randomize"])
        if cache_dir
        else None
    )
    if path is not None and path.exists():
        return read_cached(path)
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
