"""Leave-one-out evaluation of retrieval (`zooctl bench retrieval`, `bench/retrieval.py`).

For every asset of a bank: render a query video of it (one random clip, one random camera held
for the whole clip, a random background), search the bank *without* that asset, and check whether
the top results share its body plan (top-1, top-3; top-1 also over the "answerable" queries
only, those whose body plan another asset of the bank has) and, where the bank holds an asset with the
same skeleton (identical joint names), whether the top-1 is such a skeleton twin.

Body-plan labels: `BODY_PLANS` names the 28 shared Quaternius assets; procedural starter assets
carry theirs in ``meta["body_plan"]`` (mapped through `STARTER_PLANS`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .query import QueryFrames, classifier_crops, crops_from_frames
from .views import asset_colors, light_direction, random_background, shade_frames

BODY_PLANS = {
    **dict.fromkeys(["Alpaca", "Bull", "Cow", "Deer", "Fox", "Horse", "ShibaInu", "Wolf"], "quadruped"),
    **dict.fromkeys(["Trex", "Parasaurolophus"], "biped dinosaur"),
    **dict.fromkeys(["Apatosaurus", "Stegosaurus"], "quadruped dinosaur"),
    **dict.fromkeys(
        [
            "Anglerfish",
            "Koi",
            "Puffer",
            "Swordfish",
            "Dolphin",
            "Fish1",
            "Fish2",
            "Fish3",
            "Manta_ray",
            "Whale",
        ],
        "fish",
    ),
    "Snake": "snake",
    "Spider": "spider",
    **dict.fromkeys(["Wasp", "Bee"], "insect"),
    "Crab": "crab",
    "Character": "humanoid",
}
STARTER_PLANS = {
    "quadruped": "quadruped",
    "biped": "humanoid",
    "dinosaur": "biped dinosaur",
    "bird": "bird",
    "fish": "fish",
    "snake": "snake",
    "insect": "insect",
    "spider": "spider",
    "crab": "crab",
    "humanoid": "humanoid",
}


def body_plan(asset) -> str | None:
    """The body-plan label of an asset, or None when it has none."""
    return plan_label(asset.name, asset.meta)


def plan_label(name: str, meta: Any) -> str | None:
    """The body-plan label of the asset called ``name`` with ``meta`` (its own, or a bank card's)."""
    plan = meta.get("body_plan") if isinstance(meta, dict) else None
    if plan:
        return STARTER_PLANS.get(plan, plan)
    return BODY_PLANS.get(name)


def render_query_video(
    asset,
    n_frames: int = 8,
    size: int = 224,
    seed: int = 0,
    render_size: int = 320,
    device: str = "cpu",
    style: str | None = None,
) -> QueryFrames:
    """A synthetic query: ``n_frames`` frames of one random clip, seen by one random camera.

    Returns the frames cropped like a real query with ground-truth masks (`QueryFrames`).
    ``style``: one of `zooctl.retrieval.styles.HELDOUT_STYLES`, drawn the way the bank's views
    never are (the same clip, camera azimuth and background as without it for one ``seed``).
    """
    from ..render.preview import fit_camera
    from .styles import check_style, style_colors, style_elevation, style_light, style_pixels

    check_style(style)
    rng = np.random.default_rng(seed)
    if asset.clips:
        clip = list(asset.clips.values())[int(rng.integers(len(asset.clips)))]
        idx = np.unique(np.linspace(0, clip.num_frames - 1, n_frames).round().astype(int))
        posed = asset.pose(clip.name, idx).astype(np.float32)
    else:
        posed = asset.pose(None)[None].astype(np.float32)
    az, el, fov = rng.uniform(0, 360), rng.uniform(0, 35), rng.uniform(30, 50)
    el = style_elevation(el, style)
    cam = fit_camera(posed.reshape(-1, 3), render_size, render_size, az, el, fov, margin=1.1)
    n = len(posed)
    rotation = cam.rotation[0].numpy().astype(np.float64)
    light = light_direction(rng, rotation)
    bg = random_background(rng, render_size)
    light, ambient = style_light(light, rotation, float(rng.uniform(0.25, 0.45)), style)
    rgb, sil = shade_frames(
        posed,
        asset.faces,
        style_colors(asset_colors(asset), style),
        [cam] * n,
        np.repeat(light[None], n, 0),
        np.full(n, ambient),
        np.full(n, rng.uniform(0.85, 1.15)),
        [bg] * n,
        device,
    )
    rgb = style_pixels(rgb, sil, style, seed)
    images, masks, chosen = crops_from_frames(rgb, sil, n_frames, size)
    query = QueryFrames(images, masks, chosen, f"rendered {asset.name}")
    query.class_images = classifier_crops(rgb, sil, chosen, size)
    return query


@dataclass
class LooResult:
    """Per embedder set: top-1 / top-3 body-plan accuracy and top-1 skeleton accuracy, with rows."""

    embedders: list[str]
    aggregation: str
    fusion: str
    top1_plan: float
    top3_plan: float
    top1_skeleton: float | None
    top1_plan_answerable: float | None
    queries: int
    skeleton_queries: int
    rows: list[dict[str, Any]] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return dict(self.__dict__)


def leave_one_out(
    bank,
    assets: list,
    query_embeddings: dict[str, dict[str, np.ndarray]],
    embedders: list[str],
    aggregation: str = "nearest",
    fusion: str = "zsum",
    k: int = 5,
    queries: set[str] | None = None,
    query_classes: dict[str, np.ndarray] | None = None,
    semantic_weight: float | None = None,
) -> LooResult:
    """Score each asset's query against the bank minus that asset.

    ``query_embeddings[name][embedder]`` holds the (K, D) query embeddings of each asset;
    ``queries``: the assets to query (default: all; the others only sit in the bank);
    ``query_classes[name]``: its (K, 1000) ImageNet probabilities, for the semantic term
    (weight ``semantic_weight``; without them, appearance only).
    """
    from .search import score_bank

    plans = {a.name: body_plan(a) for a in assets}
    skeleton = {a.name: tuple(a.joint_names) for a in assets}
    rows = []
    for a in assets:
        if plans[a.name] is None or (queries is not None and a.name not in queries):
            continue
        q = {e: query_embeddings[a.name][e] for e in embedders}
        classes = (query_classes or {}).get(a.name)
        res = score_bank(
            bank,
            q,
            classes=classes,
            aggregation=aggregation,
            fusion=fusion,
            k=k,
            exclude={a.name},
            semantic_weight=semantic_weight,
        )
        ranked = [m.name for m in res.matches]
        twins = [b.name for b in assets if b.name != a.name and skeleton[b.name] == skeleton[a.name]]
        rows.append(
            {
                "query": a.name,
                "plan": plans[a.name],
                "top": ranked[:3],
                "top_plans": [plans.get(n) for n in ranked[:3]],
                "top1_plan": plans.get(ranked[0]) == plans[a.name],
                "top3_plan": any(plans.get(n) == plans[a.name] for n in ranked[:3]),
                "top1_skeleton": (ranked[0] in twins) if twins else None,
                "answerable": any(plans[b.name] == plans[a.name] for b in assets if b.name != a.name),
            }
        )
    sk = [r["top1_skeleton"] for r in rows if r["top1_skeleton"] is not None]
    ans = [r["top1_plan"] for r in rows if r["answerable"]]
    n = max(len(rows), 1)
    return LooResult(
        embedders,
        aggregation,
        fusion,
        sum(r["top1_plan"] for r in rows) / n,
        sum(r["top3_plan"] for r in rows) / n,
        (sum(sk) / len(sk)) if sk else None,
        (sum(ans) / len(ans)) if ans else None,
        len(rows),
        len(sk),
        rows,
    )
