"""Small synthetic shapes for tests and benchmarks: a skinned tube rig and a UV sphere.

These are exact, analytic inputs (no data files), so tests that use them can check against
known answers; real-asset tests use the Quaternius glTF files instead.
"""

from __future__ import annotations

import numpy as np

from ..asset import Clip, RiggedAsset, sparsify_weights
from ..geometry import compose_trs


def uv_sphere(faces: int = 2000, radius: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A closed UV sphere with about ``faces`` triangles: vertices (V, 3) float32, faces (F, 3) int64.

    Faces are wound counter-clockwise seen from outside.
    """
    rings = max(3, int(round(np.sqrt(faces / 4.0))))
    segs = max(3, int(round(faces / (2.0 * (rings - 1)))))
    theta = np.linspace(0.0, np.pi, rings + 1)[1:-1]  # latitude rings without the poles
    phi = np.linspace(0.0, 2.0 * np.pi, segs, endpoint=False)
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    ring = np.stack((st * np.cos(phi), ct * np.ones_like(phi), -st * np.sin(phi)), -1).reshape(-1, 3)
    verts = np.concatenate(([[0.0, 1.0, 0.0]], ring, [[0.0, -1.0, 0.0]])) * radius
    top, bottom = 0, len(verts) - 1
    f = []
    idx = lambda r, s: 1 + r * segs + (s % segs)  # noqa: E731
    for s in range(segs):
        f.append((top, idx(0, s), idx(0, s + 1)))
        f.append((bottom, idx(rings - 2, s + 1), idx(rings - 2, s)))
    for r in range(rings - 2):
        for s in range(segs):
            a, b, c, d = idx(r, s), idx(r, s + 1), idx(r + 1, s), idx(r + 1, s + 1)
            f.append((a, c, b))
            f.append((b, c, d))
    return verts.astype(np.float32), np.asarray(f, dtype=np.int64)


def tube_asset(
    bones: int = 2,
    bone_length: float = 1.0,
    radius: float = 0.15,
    rings_per_bone: int = 8,
    segments: int = 16,
    blend: float = 0.25,
    name: str = "tube",
) -> RiggedAsset:
    """A capped tube along +X with a chain of ``bones`` joints (joint k at x = k * bone_length).

    Skin weights blend linearly between neighbouring bones over ``blend * bone_length`` either
    side of each inner joint. The asset has one clip, ``bend``, that bends every joint about Z.
    """
    n_rings = bones * rings_per_bone + 1
    xs = np.linspace(0.0, bones * bone_length, n_rings)
    phi = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    ring = np.stack((np.zeros_like(phi), radius * np.cos(phi), radius * np.sin(phi)), -1)
    verts = (ring[None] + xs[:, None, None] * np.array([1.0, 0.0, 0.0])).reshape(-1, 3)
    caps = np.array([[0.0, 0.0, 0.0], [bones * bone_length, 0.0, 0.0]])
    verts = np.concatenate((verts, caps))
    c0, c1 = len(verts) - 2, len(verts) - 1
    faces = []
    for r in range(n_rings - 1):
        for s in range(segments):
            a, b = r * segments + s, r * segments + (s + 1) % segments
            c, d = a + segments, b + segments
            faces += [(a, b, c), (b, d, c)]
    last = (n_rings - 1) * segments
    for s in range(segments):
        faces.append((c0, (s + 1) % segments, s))
        faces.append((c1, last + s, last + (s + 1) % segments))
    # Weights: bone k owns [k L, (k+1) L]; linear ramps of half-width blend*L around inner joints.
    x = verts[:, 0] / bone_length
    dense = np.zeros((len(verts), bones))
    for k in range(bones):
        lo = np.clip((x - (k - blend)) / (2 * blend), 0, 1) if k > 0 else np.ones_like(x)
        hi = np.clip(((k + 1 + blend) - x) / (2 * blend), 0, 1) if k < bones - 1 else np.ones_like(x)
        dense[:, k] = np.minimum(lo, hi)
    dense /= dense.sum(1, keepdims=True)
    sj, sw = sparsify_weights(dense.astype(np.float32), k=min(4, bones))
    parents = np.arange(-1, bones - 1, dtype=np.int32)
    t = np.zeros((bones, 3))
    t[1:, 0] = bone_length
    q = np.tile([1.0, 0.0, 0.0, 0.0], (bones, 1))
    s = np.ones((bones, 3))
    rest = compose_trs(t, q, s)
    glob = np.empty_like(rest)
    for j, p in enumerate(parents):
        glob[j] = rest[j] if p < 0 else glob[p] @ rest[j]
    frames = 5
    ang = np.linspace(0.0, 0.6, frames)[:, None] * np.ones((1, bones))
    ang[:, 0] = 0.0
    rot = np.stack((np.cos(ang / 2), 0 * ang, 0 * ang, np.sin(ang / 2)), -1)
    clip = Clip("bend", 30.0, rot, np.broadcast_to(t, (frames, bones, 3)).copy(), np.ones((frames, bones, 3)))
    return RiggedAsset(
        name=name,
        vertices=verts.astype(np.float32),
        faces=np.asarray(faces, dtype=np.int32),
        joint_names=[f"bone{k}" for k in range(bones)],
        parents=parents,
        rest_local=rest,
        inverse_bind=np.linalg.inv(glob),
        skin_joints=sj,
        skin_weights=sw,
        clips={"bend": clip},
    ).validate()
