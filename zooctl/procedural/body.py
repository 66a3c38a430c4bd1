"""Proportions, parts and assembly: turning a body plan into a skinned, animated `RiggedAsset`."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..asset import RiggedAsset, check_name
from .mesh import Part, polyline, tube
from .motion import ClipBuilder
from .skeleton import SkeletonBuilder
from .skinning import chain_weights, sparse


@dataclass(frozen=True)
class BodyParams:
    """Proportions of a procedural animal, in metres.

    A body plan uses the ones that apply to it (a fish has no legs or neck; a snake's
    ``tail_length`` is the tapering end of its body); ``wing_length`` is one wing, for birds.
    """

    body_length: float
    leg_length: float
    neck_length: float
    tail_length: float
    head_size: float
    girth: float
    wing_length: float = 0.0

    def jittered(self, rng: np.random.Generator, amount: float = 0.06) -> BodyParams:
        """Every proportion scaled by its own random factor in [1 - amount, 1 + amount]."""
        vals = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return BodyParams(**{k: float(v * (1.0 + rng.uniform(-amount, amount))) for k, v in vals.items()})

    def replace(self, **changes: float) -> BodyParams:
        return dataclasses.replace(self, **changes)


Motion = Callable[[ClipBuilder], None]


@dataclass
class Body:
    """A body plan instantiated with proportions: the skeleton, the parts and the clip makers.

    motions maps clip name -> (frames per loop, function that animates a `ClipBuilder`).
    """

    plan: str
    params: BodyParams
    skeleton: SkeletonBuilder
    parts: list[Part]
    motions: dict[str, tuple[int, Motion]] = field(default_factory=dict)


def limb_part(
    name: str,
    points: list[np.ndarray],
    radius_top: float,
    radius_tip: float,
    chain: list[str],
    anchor: str | None,
    color: np.ndarray,
    up: tuple[float, float, float] = (0.0, 0.0, -1.0),
    n: int = 20,
    segments: int = 12,
    flatten: float = 1.0,
) -> Part:
    """A tapering round tube through ``points`` with rounded ends (legs, arms, tails, necks).

    ``flatten`` scales the "up" radius (1: round cross-section).
    """
    line = polyline(points, n)
    x = np.linspace(0.0, 1.0, n)
    r = radius_top + (radius_tip - radius_top) * x
    ends = np.minimum(x, 1.0 - x)
    rounded = np.sqrt(np.clip(1.0 - (np.clip(0.08 - ends, 0.0, None) / 0.08) ** 2, 0.05, 1.0))
    r = r * rounded
    return Part(
        name, line, np.stack([r, r * flatten], 1), np.asarray(up, float), chain, anchor, color, None, segments
    )


def blob_part(
    name: str,
    start: np.ndarray,
    end: np.ndarray,
    side: float,
    up_radius: float,
    chain: list[str],
    anchor: str | None,
    color: np.ndarray,
    up: tuple[float, float, float] = (0.0, 1.0, 0.0),
    n: int = 16,
    segments: int = 16,
    taper: float = 0.0,
    belly: np.ndarray | None = None,
) -> Part:
    """An ellipsoid-like closed blob from ``start`` to ``end`` (heads, bodies, eyes); ``taper``
    narrows the end side (0: symmetric, 0.5: half as wide towards ``end``)."""
    line = polyline([np.asarray(start, float), np.asarray(end, float)], n)
    x = np.linspace(0.0, 1.0, n)
    prof = np.sqrt(np.clip(1.0 - (2 * x - 1) ** 2, 0.0, 1.0)) * (1.0 - taper * x)
    return Part(
        name,
        line,
        np.stack([side * prof, up_radius * prof], 1),
        np.asarray(up, float),
        chain,
        anchor,
        color,
        belly,
        segments,
    )


def assemble(body: Body, name: str, meta: dict | None = None) -> RiggedAsset:
    """Mesh, weight, colour and animate a `Body` into a validated `RiggedAsset`."""
    check_name(name, "asset name")
    names, parents, pos, rest, inv_bind = body.skeleton.arrays()
    J = len(names)
    verts, faces, colors, dense = [], [], [], []
    offset = 0
    for part in body.parts:
        v, f, line_idx, under = tube(part)
        chain_idx = np.array([names.index(j) for j in part.chain])
        chain_pos = pos[chain_idx]
        tip = part.centerline[-1]  # the last bone runs from the last chain joint to the part's end
        lengths = np.linalg.norm(np.diff(np.concatenate([chain_pos, tip[None]]), axis=0), axis=1)
        falloff = 0.35 * float(np.mean(lengths[lengths > 1e-9])) if np.any(lengths > 1e-9) else 1.0
        anchor_pos = None if part.anchor is None else pos[names.index(part.anchor)]
        w_line = chain_weights(part.centerline, chain_pos, tip, anchor_pos, falloff)
        w = np.zeros((len(v), J))
        w[:, chain_idx] = w_line[line_idx, :-1]
        if part.anchor is not None:
            w[:, names.index(part.anchor)] += w_line[line_idx, -1]
        base = np.asarray(part.color, float)
        belly = base if part.belly is None else np.asarray(part.belly, float)
        col = base[None] * (1 - under[:, None]) + belly[None] * under[:, None]
        verts.append(v)
        faces.append(f + offset)
        colors.append(col)
        dense.append(w)
        offset += len(v)
    vertices = np.concatenate(verts).astype(np.float32)
    sj, sw = sparse(np.concatenate(dense), 4)
    asset = RiggedAsset(
        name=name,
        vertices=vertices,
        faces=np.concatenate(faces).astype(np.int32),
        joint_names=names,
        parents=parents,
        rest_local=rest,
        inverse_bind=inv_bind,
        skin_joints=sj,
        skin_weights=sw,
        vertex_colors=np.clip(np.concatenate(colors), 0, 1).astype(np.float32),
        meta=dict(meta or {}),
    )
    for clip_name, (frames, motion) in body.motions.items():
        builder = ClipBuilder(names, rest, frames)
        motion(builder)
        asset.clips[clip_name] = builder.clip(clip_name)
    return asset.validate()
