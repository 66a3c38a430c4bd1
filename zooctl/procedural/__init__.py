"""Procedural starter animals: rigged, skinned and animated from code, with no downloaded data.

`build_animal(plan, params, seed)` makes one animal; `starter_assets(seed)` makes the whole starter
bank (every body plan in a few proportion variants); `seed_bank(bank, seed)` adds it to a bank.
Everything is deterministic for a given seed.
"""

from __future__ import annotations

import colorsys
import zlib
from collections.abc import Callable
from typing import Any

import numpy as np

from ..asset import RiggedAsset
from ..errors import InputError
from .arthropods import CRAB, INSECT, SPIDER, build_crab, build_insect, build_spider
from .body import Body, BodyParams, assemble
from .vertebrates import (
    BIPED,
    BIRD,
    DINOSAUR,
    FISH,
    QUADRUPED,
    SNAKE,
    build_biped,
    build_bird,
    build_dinosaur,
    build_fish,
    build_quadruped,
    build_snake,
)

__all__ = ["PLANS", "VARIANTS", "BodyParams", "build_animal", "starter_assets", "seed_bank"]

# plan -> (default proportions, builder)
PLANS: dict[str, tuple[BodyParams, Callable[..., Body]]] = {
    "quadruped": (QUADRUPED, build_quadruped),
    "biped": (BIPED, build_biped),
    "bird": (BIRD, build_bird),
    "fish": (FISH, build_fish),
    "snake": (SNAKE, build_snake),
    "insect": (INSECT, build_insect),
    "spider": (SPIDER, build_spider),
    "dinosaur": (DINOSAUR, build_dinosaur),
    "crab": (CRAB, build_crab),
}

# Proportion variants per plan: asset-name suffix -> changed proportions (in metres).
VARIANTS: dict[str, dict[str, dict[str, float]]] = {
    "quadruped": {
        "": {},
        "longneck": {"neck_length": 0.9, "leg_length": 0.9, "tail_length": 0.3, "head_size": 0.17},
        "stout": {
            "leg_length": 0.3,
            "body_length": 1.15,
            "girth": 0.24,
            "tail_length": 0.35,
            "neck_length": 0.2,
        },
    },
    "biped": {"": {}, "tailed": {"tail_length": 0.7, "leg_length": 0.6, "head_size": 0.15, "girth": 0.17}},
    "bird": {
        "": {},
        "longlegs": {"leg_length": 0.45, "neck_length": 0.3, "tail_length": 0.1, "wing_length": 0.6},
    },
    "fish": {"": {}, "deep": {"girth": 0.22, "body_length": 0.5, "tail_length": 0.15, "head_size": 0.16}},
    "snake": {"": {}, "thick": {"body_length": 1.6, "girth": 0.09, "head_size": 0.11, "tail_length": 0.35}},
    "insect": {"": {}, "longlegs": {"leg_length": 0.4, "body_length": 0.36}},
    "spider": {"": {}, "longlegs": {"leg_length": 0.6, "girth": 0.07}},
    "dinosaur": {
        "": {},
        "duckbill": {"head_size": 0.2, "neck_length": 0.45, "leg_length": 0.7, "tail_length": 1.1},
    },
    "crab": {"": {}, "wide": {"body_length": 0.4, "head_size": 0.11, "leg_length": 0.24}},
}

# Base hues (0..1) per plan, for colours that read at a glance on a contact sheet.
_HUES = {
    "quadruped": 0.08,
    "biped": 0.07,
    "bird": 0.6,
    "fish": 0.52,
    "snake": 0.3,
    "insect": 0.13,
    "spider": 0.0,
    "dinosaur": 0.25,
    "crab": 0.02,
}


def palette(
    plan: str, rng: np.random.Generator, any_hue: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(main, secondary, belly) linear RGB colours of one animal, jittered around the plan's hue
    (``any_hue``: any hue, brightness and contrast, so that colour says nothing about the plan)."""
    if any_hue:
        h, sat, val = rng.uniform(0, 1), rng.uniform(0.05, 0.85), rng.uniform(0.2, 0.9)
        main = np.array(colorsys.hsv_to_rgb(h, sat, val))
        h2 = (h + rng.choice([rng.uniform(-0.08, 0.08), rng.uniform(0, 1)])) % 1.0
        second = np.array(colorsys.hsv_to_rgb(h2, rng.uniform(0.05, 0.9), rng.uniform(0.1, 0.95)))
        belly = np.array(
            colorsys.hsv_to_rgb(h, sat * rng.uniform(0.1, 1), min(1.0, val * rng.uniform(0.7, 1.5)))
        )
        return main, second, belly
    h = (_HUES.get(plan, 0.1) + rng.uniform(-0.05, 0.05)) % 1.0
    sat = rng.uniform(0.35, 0.7) if plan != "spider" else rng.uniform(0.0, 0.15)
    val = rng.uniform(0.45, 0.8) if plan != "spider" else rng.uniform(0.2, 0.35)
    main = np.array(colorsys.hsv_to_rgb(h, sat, val))
    second = np.array(colorsys.hsv_to_rgb((h + rng.uniform(-0.06, 0.06)) % 1.0, sat * 0.9, val * 0.75))
    belly = np.array(colorsys.hsv_to_rgb(h, sat * 0.35, min(1.0, val * 1.25)))
    return main, second, belly


def _rng(seed: int, name: str) -> np.random.Generator:
    """A generator that depends on the seed and the animal's name only (not on build order)."""
    return np.random.default_rng([int(seed) & 0xFFFFFFFF, zlib.crc32(name.encode())])


def build_animal(
    plan: str,
    params: BodyParams | None = None,
    seed: int = 0,
    name: str | None = None,
    jitter: float = 0.0,
    meta: dict[str, Any] | None = None,
    any_hue: bool = False,
) -> RiggedAsset:
    """One procedural animal of body plan ``plan`` (see `PLANS`).

    ``params`` defaults to the plan's proportions; ``jitter`` (e.g. 0.06) scales each proportion by
    a seeded random factor in [1 - jitter, 1 + jitter]. Colours come from the seed (around the
    plan's hue, or any hue with ``any_hue``).
    """
    if plan not in PLANS:
        raise InputError(f"unknown body plan {plan!r}", hint=f"plans: {', '.join(PLANS)}")
    default, builder = PLANS[plan]
    name = name or plan
    rng = _rng(seed, name)
    p = params or default
    if jitter > 0:
        p = p.jittered(rng, jitter)
    for field_name in ("body_length", "head_size", "girth"):
        if getattr(p, field_name) <= 0:
            raise InputError(f"{field_name} must be positive, got {getattr(p, field_name)}")
    body = builder(p, palette(plan, rng, any_hue))
    info = {
        "tags": ["procedural", plan],
        "license": "CC0-1.0",
        "source": f"zooctl procedural {plan} (seed {seed})",
        "meters_per_unit": 1.0,
        "body_plan": plan,
        "proportions": {k: round(float(getattr(p, k)), 4) for k in p.__dataclass_fields__},
    }
    info.update(meta or {})
    return assemble(body, name, info)


def starter_assets(seed: int = 0, plans: list[str] | None = None, variants: bool = True) -> list[RiggedAsset]:
    """The starter bank: every plan (or those named) in each of its proportion variants."""
    out = []
    for plan in plans or list(PLANS):
        if plan not in PLANS:
            raise InputError(f"unknown body plan {plan!r}", hint=f"plans: {', '.join(PLANS)}")
        default, _ = PLANS[plan]
        for suffix, change in VARIANTS[plan].items():
            if suffix and not variants:
                continue
            name = f"{plan}-{suffix}" if suffix else plan
            out.append(build_animal(plan, default.replace(**change), seed=seed, name=name, jitter=0.05))
    return out


def seed_bank(
    bank: Any,
    seed: int = 0,
    plans: list[str] | None = None,
    variants: bool = True,
    replace: bool = False,
    assets: list[RiggedAsset] | None = None,
) -> list[str]:
    """Add the starter animals to ``bank`` (anything with ``add(asset, replace=...)`` and
    ``exists(name)``, such as `zooctl.store.bank.Bank`), or ``assets`` instead when given (e.g.
    random animals, `zooctl.procedural.random.random_assets`). Existing names are kept unless
    ``replace``.

    Returns the names added.
    """
    if assets is None:
        assets = starter_assets(seed, plans, variants)
    added = []
    for asset in assets:
        if not replace and bank.exists(asset.name):
            continue
        bank.add(asset, replace=replace)
        added.append(asset.name)
    return added
