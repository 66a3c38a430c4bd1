"""The rig data model: `RiggedAsset` and its animation `Clip`s.

Internal convention (the same as glTF 2.0, so imported assets need no conversion):

- Y up, right-handed, -Z forward where a forward exists; lengths in model units, with
  ``meta["meters_per_unit"]`` saying how many metres one unit is (1.0 for glTF).
- Quaternions (w, x, y, z); 4x4 matrices act on column vectors; local transforms are T @ R @ S.
- Joints are topologically sorted: ``parents[j] < j`` for every non-root joint, roots have -1.
- ``vertices`` are in *bind space*: the skinned position of vertex i at a pose is
  ``sum_k w_ik * G_k @ inverse_bind[k] @ v_i`` with ``G_k`` the joint-to-model transform of joint k
  (linear blend skinning, as glTF and UsdSkel define it).
- Skin weights are stored sparse: ``skin_joints`` (V, K) int32 and ``skin_weights`` (V, K) float32,
  rows summing to one, sorted by decreasing weight, padded with weight 0.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .errors import InputError
from .geometry import compose_trs, decompose_trs, global_transforms
from .names import check_name, sanitize_name  # noqa: F401  (re-exported)


@dataclass
class Clip:
    """Per-frame local joint transforms sampled at ``fps``.

    rotations: (T, J, 4) wxyz; translations: (T, J, 3); scales: (T, J, 3).
    """

    name: str
    fps: float
    rotations: np.ndarray
    translations: np.ndarray
    scales: np.ndarray

    @property
    def num_frames(self) -> int:
        return int(self.rotations.shape[0])

    @property
    def duration(self) -> float:
        return (self.num_frames - 1) / self.fps if self.num_frames > 1 else 0.0

    def local_matrices(self, frames: np.ndarray | slice | int | None = None) -> np.ndarray:
        """(T', J, 4, 4) local transforms of the chosen frames (all by default)."""
        sel = slice(None) if frames is None else frames
        return compose_trs(self.translations[sel], self.rotations[sel], self.scales[sel])


@dataclass
class RiggedAsset:
    """A skinned, rigged mesh with its animation clips. See the module docstring for conventions."""

    name: str
    vertices: np.ndarray  # (V, 3) float32, bind space
    faces: np.ndarray  # (F, 3) int32
    joint_names: list[str]
    parents: np.ndarray  # (J,) int32
    rest_local: np.ndarray  # (J, 4, 4) float64 rest (node) local transforms
    inverse_bind: np.ndarray  # (J, 4, 4) float64
    skin_joints: np.ndarray  # (V, K) int32
    skin_weights: np.ndarray  # (V, K) float32
    clips: dict[str, Clip] = field(default_factory=dict)
    uvs: np.ndarray | None = None  # (V, 2) float32
    vertex_colors: np.ndarray | None = None  # (V, 3) float32 in [0, 1], linear
    texture_png: bytes | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    # -- sizes ----------------------------------------------------------------------------
    @property
    def num_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def num_faces(self) -> int:
        return int(self.faces.shape[0])

    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    def bbox(self) -> tuple[list[float], list[float]]:
        """Rest-pose axis-aligned bounding box (min, max) in model units."""
        v = self.pose()
        return v.min(0).astype(float).tolist(), v.max(0).astype(float).tolist()

    def size(self) -> float:
        """Diagonal of the rest-pose bounding box: the model's scale for tolerances."""
        lo, hi = self.bbox()
        return float(np.linalg.norm(np.subtract(hi, lo)))

    def skin_weights_dense(self) -> np.ndarray:
        """(V, J) dense skinning weights."""
        dense = np.zeros((self.num_vertices, self.num_joints), dtype=np.float32)
        np.add.at(dense, (np.arange(self.num_vertices)[:, None], self.skin_joints), self.skin_weights)
        return dense

    def depth(self) -> np.ndarray:
        """(J,) depth of each joint in the tree (roots 0)."""
        d = np.zeros(self.num_joints, dtype=np.int32)
        for j, p in enumerate(self.parents):
            d[j] = 0 if p < 0 else d[p] + 1
        return d

    def rest_trs(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Rest local transforms as translation (J,3), wxyz (J,4), scale (J,3)."""
        return decompose_trs(self.rest_local)

    # -- posing ---------------------------------------------------------------------------
    def joint_transforms(self, local: np.ndarray | None = None) -> np.ndarray:
        """(..., J, 4, 4) joint-to-model transforms for local transforms (rest pose by default)."""
        return global_transforms(self.rest_local if local is None else local, self.parents)

    def skinning_matrices(self, local: np.ndarray | None = None) -> np.ndarray:
        """(..., J, 4, 4) ``G_k @ inverse_bind[k]`` for the given local transforms."""
        return self.joint_transforms(local) @ self.inverse_bind

    def pose(self, clip: str | None = None, frame: int | np.ndarray = 0) -> np.ndarray:
        """Skinned vertex positions (V, 3) of one clip frame, or (T, V, 3) for an array of frames.

        With ``clip=None`` the rest pose is used.
        """
        if clip is None:
            local = self.rest_local
        else:
            c = self.clips.get(clip)
            if c is None:
                raise InputError(
                    f"asset {self.name!r} has no clip {clip!r}",
                    hint=f"clips: {', '.join(self.clips) or 'none'}",
                )
            local = c.local_matrices(frame)
        return lbs(self.vertices, self.skin_joints, self.skin_weights, self.skinning_matrices(local))

    def bind_joint_positions(self) -> np.ndarray:
        """(J, 3) joint origins in bind space (inverse of the inverse bind matrices)."""
        return np.linalg.inv(self.inverse_bind)[:, :3, 3]

    def validate(self) -> RiggedAsset:
        """Check every invariant; raise `InputError` naming the first one broken."""
        check_name(self.name, "asset name")
        V, J = self.num_vertices, self.num_joints

        def bad(msg: str) -> InputError:
            return InputError(f"asset {self.name!r}: {msg}")

        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3 or V == 0:
            raise bad(f"vertices must be a non-empty (V, 3) array, got {self.vertices.shape}")
        if self.faces.ndim != 2 or self.faces.shape[1] != 3 or self.faces.shape[0] == 0:
            raise bad(f"faces must be a non-empty (F, 3) array, got {self.faces.shape}")
        if self.faces.min() < 0 or self.faces.max() >= V:
            raise bad("face indices out of range")
        if J == 0:
            raise bad("no joints")
        if len(set(self.joint_names)) != J:
            raise bad("joint names are not unique")
        if self.parents.shape != (J,) or any(not (-1 <= p < j) for j, p in enumerate(self.parents)):
            raise bad("parents must be topologically sorted (parents[j] < j, roots -1)")
        for arr, nm in ((self.rest_local, "rest_local"), (self.inverse_bind, "inverse_bind")):
            if arr.shape != (J, 4, 4) or not np.all(np.isfinite(arr)):
                raise bad(f"{nm} must be finite (J, 4, 4)")
        sv = np.linalg.svd(self.inverse_bind[:, :3, :3], compute_uv=False)
        if np.any(sv[:, -1] <= 1e-9 * sv[:, 0]):  # bind_joint_positions inverts them
            raise bad("inverse_bind matrices must be invertible (a joint bound with zero scale?)")
        if not np.all(np.isfinite(self.vertices)):
            raise bad("vertices contain NaN or infinity")
        sj, sw = self.skin_joints, self.skin_weights
        if sj.shape != sw.shape or sj.ndim != 2 or sj.shape[0] != V:
            raise bad("skin_joints and skin_weights must both be (V, K)")
        if not np.all(np.isfinite(sw)):
            raise bad("skin weights contain NaN or infinity")
        if np.any(sw < 0):
            raise bad("skin weights are negative")
        if sj.min() < 0 or sj.max() >= J:
            raise bad(f"skin joint indices out of range [0, {J})")
        sums = sw.sum(1)
        if np.any(np.abs(sums - 1) > 1e-3):
            raise bad(f"skin weights of {(np.abs(sums - 1) > 1e-3).sum()} vertices do not sum to 1")
        mats = self.skinning_matrices()
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        for s in range(0, V, 65536):  # in chunks: skinning a whole large mesh at once takes ~2 kB a vertex
            part = slice(s, s + 65536)
            v = lbs(self.vertices[part], sj[part], sw[part], mats)
            lo, hi = np.minimum(lo, v.min(0)), np.maximum(hi, v.max(0))
        if not np.max(hi - lo) > 0:
            raise bad("the rest pose collapses to a single point (a joint with zero scale?)")
        for c in self.clips.values():
            T = c.num_frames
            if (
                c.rotations.shape != (T, J, 4)
                or c.translations.shape != (T, J, 3)
                or c.scales.shape != (T, J, 3)
            ):
                raise bad(f"clip {c.name!r} arrays do not match {J} joints")
            if T == 0 or not (c.fps > 0):
                raise bad(f"clip {c.name!r} is empty or has a bad fps")
            if not all(np.all(np.isfinite(a)) for a in (c.rotations, c.translations, c.scales)):
                raise bad(f"clip {c.name!r} contains NaN or infinity")
        if self.uvs is not None and self.uvs.shape != (V, 2):
            raise bad("uvs must be (V, 2)")
        if self.vertex_colors is not None and self.vertex_colors.shape != (V, 3):
            raise bad("vertex_colors must be (V, 3)")
        return self

    def summary(self) -> dict[str, Any]:
        """What `bank list` shows and the bank index stores."""
        lo, hi = self.bbox()
        return {
            "name": self.name,
            "vertices": self.num_vertices,
            "faces": self.num_faces,
            "joints": self.num_joints,
            "clips": {c.name: {"frames": c.num_frames, "fps": float(c.fps)} for c in self.clips.values()},
            "bbox": [lo, hi],
            "tags": list(self.meta.get("tags", [])),
            "license": self.meta.get("license", ""),
            "source": self.meta.get("source", ""),
            "has_texture": self.texture_png is not None,
            # what animal it is (`zooctl.retrieval.labels`): absent until labelled
            **{k: self.meta[k] for k in LABEL_KEYS if isinstance(self.meta.get(k), str)},
        }


LABEL_KEYS = ("label", "label_source")  # the asset's animal label and where it came from


def lbs(
    vertices: np.ndarray, skin_joints: np.ndarray, skin_weights: np.ndarray, mats: np.ndarray
) -> np.ndarray:
    """Linear blend skinning in numpy.

    vertices (V, 3); skin_joints, skin_weights (V, K); mats (..., J, 4, 4) skinning matrices.
    Returns (..., V, 3). Poses are skinned a few at a time: the per-vertex matrices take 64 times
    the output's memory (a 2,400-frame clip of a 4,000-vertex mesh: 4.9 GB at once).
    """
    lead, (J, V, K) = mats.shape[:-3], (mats.shape[-3], *skin_joints.shape)
    flat = mats.reshape(-1, J, 4, 4)
    w, v = skin_weights.astype(np.float64), vertices.astype(np.float64)
    out = np.empty((len(flat), V, 3))
    step = max(1, LBS_CHUNK_BYTES // max(1, V * K * 16 * 8))
    for s in range(0, len(flat), step):
        m = flat[s : s + step, skin_joints]  # (B, V, K, 4, 4)
        blended = np.einsum("vk,bvkij->bvij", w, m)
        out[s : s + step] = np.einsum("bvij,vj->bvi", blended[..., :3, :3], v) + blended[..., :3, 3]
    return out.reshape(*lead, V, 3)


LBS_CHUNK_BYTES = 64 << 20


def sparsify_weights(dense: np.ndarray, k: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """(V, J) weights -> top-k (joints, weights) renormalised to sum 1, sorted descending."""
    k = min(k, dense.shape[1])
    idx = np.argsort(-dense, axis=1)[:, :k]
    w = np.take_along_axis(dense, idx, axis=1).clip(min=0)
    s = w.sum(1, keepdims=True)
    w = np.where(s > 0, w / np.where(s > 0, s, 1), np.eye(1, k, 0))
    return idx.astype(np.int32), w.astype(np.float32)
