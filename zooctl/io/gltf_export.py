"""glTF 2.0 binary (``.glb``) export: mesh, skin, inverse bind matrices, animations, texture.

The zooctl convention is glTF's (Y up, metres, wxyz only differs as xyzw in the file, column-major
matrices), so nothing is converted: one node per joint with its bind-pose transform as TRS (see
`_node_pose`: what glTF readers expect, and what makes Blender deform exactly), one mesh
node bound to one skin over every joint, one animation per clip with LINEAR samplers at the clip's
frame times. Every animation has channels for every joint that moves in any exported clip (so that
switching clips in Blender or three.js leaves no bone at another clip's pose); a joint that stays
at rest in all of them gets none (its node keeps the rest transform, as glTF specifies). Vertex colours are ``COLOR_0``; UVs and a
texture become ``TEXCOORD_0`` and the material's ``baseColorTexture``.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..asset import RiggedAsset
from ..errors import InputError, UsageError
from ..geometry import compose_trs, decompose_trs
from ..store.fs import write_bytes_atomic
from .usd_export import animated_joints, bind_locals, rest_differs_from_bind, select_clips

_FLOAT, _UINT8, _UINT16, _UINT32 = 5126, 5121, 5123, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
_TYPES = {1: "SCALAR", 2: "VEC2", 3: "VEC3", 4: "VEC4", 16: "MAT4"}


class _Builder:
    """Accumulates the binary buffer, buffer views and accessors of one glTF document."""

    def __init__(self) -> None:
        self.blob = bytearray()
        self.views: list[dict[str, Any]] = []
        self.accessors: list[dict[str, Any]] = []

    def view(self, data: bytes, target: int | None = None) -> int:
        while len(self.blob) % 4:
            self.blob.append(0)
        v: dict[str, Any] = {"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data)}
        if target is not None:
            v["target"] = target
        self.blob.extend(data)
        self.views.append(v)
        return len(self.views) - 1

    def accessor(
        self, arr: np.ndarray, component: int, target: int | None = None, minmax: bool = False
    ) -> int:
        """Add a tightly packed accessor for ``arr`` (N,) or (N, C) (C in 2, 3, 4, 16)."""
        dtype = {_FLOAT: np.float32, _UINT8: np.uint8, _UINT16: np.uint16, _UINT32: np.uint32}[component]
        a = np.ascontiguousarray(arr, dtype=dtype)
        ncomp = 1 if a.ndim == 1 else a.shape[1]
        acc: dict[str, Any] = {
            "bufferView": self.view(a.tobytes(), target),
            "componentType": component,
            "count": int(a.shape[0]),
            "type": _TYPES[ncomp],
        }
        if minmax:
            flat = a.reshape(len(a), -1)
            acc["min"] = [float(x) if component == _FLOAT else int(x) for x in flat.min(0)]
            acc["max"] = [float(x) if component == _FLOAT else int(x) for x in flat.max(0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1


def _vertex_normals(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """(V, 3) unit area-weighted normals; +Y where a vertex touches only degenerate faces."""
    tri = v[f].astype(np.float64)
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n = np.zeros((len(v), 3))
    for k in range(3):
        np.add.at(n, f[:, k], fn)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(length > 1e-20, n / np.maximum(length, 1e-20), [0.0, 1.0, 0.0])


def _continuous(q: np.ndarray) -> np.ndarray:
    """(T, ..., 4) quaternions with signs chosen so consecutive frames are on one hemisphere."""
    q = np.array(q, dtype=np.float64)
    for i in range(1, len(q)):
        q[i][np.sum(q[i] * q[i - 1], axis=-1) < 0] *= -1
    return q


def _frame_times(frames: int, fps: float) -> np.ndarray:
    """(T,) float32 key times i / fps, each rounded up to the next float32 where rounding to
    nearest fell below i / fps, so that a reader computing ``floor(t * fps)`` gets frame i back."""
    exact = np.arange(frames) / fps
    t = exact.astype(np.float32)
    low = t.astype(np.float64) < exact
    t[low] = np.nextafter(t[low], np.float32(np.inf))
    return t


def _exact_trs(m: np.ndarray, t: np.ndarray, q: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(J,) whether each matrix is exactly translation @ rotation @ scale (no shear)."""
    return np.abs(compose_trs(t, q, s) - m).max(axis=(1, 2)) <= 1e-6 * max(1.0, float(np.abs(m).max()))


def _node_pose(asset: RiggedAsset) -> tuple[np.ndarray, np.ndarray]:
    """The joint nodes' transforms to write, and which joints every animation must then key.

    glTF readers treat the node transforms as the pose the mesh is bound in (Blender builds its
    bones from them); an asset whose rest pose differs from its bind pose (most imported ones)
    is written with its *bind* pose as node transforms, and every joint whose rest transform
    differs from it gets keys in every animation, so each clip still plays exactly. A bind pose
    that is not TRS (sheared) keeps the rest pose. Returns (J, 4, 4) and (J,) bool.
    """
    local = bind_locals(asset)
    t, q, s = decompose_trs(local)
    if not _exact_trs(local, t, q, s).all() or not np.all(np.isfinite(local)):
        return asset.rest_local, np.zeros(asset.num_joints, bool)
    return local, rest_differs_from_bind(asset)


def gltf_document(asset: RiggedAsset, clips: Sequence[str] | None = None) -> tuple[dict[str, Any], bytes]:
    """The glTF JSON document and its binary buffer for ``asset`` with the named clips (None: all)."""
    asset.validate()
    names = select_clips(asset, clips)
    b = _Builder()
    J = asset.num_joints
    node_local, must_key = _node_pose(asset)
    t, q, s = decompose_trs(node_local)
    exact = _exact_trs(node_local, t, q, s)
    animated = np.zeros(J, bool)
    if names:
        animated[animated_joints(asset, names)] = True
        animated |= must_key
    if np.any(~exact & animated):
        j = int(np.nonzero(~exact & animated)[0][0])
        raise InputError(
            f"joint {asset.joint_names[j]!r} has a sheared rest transform, which glTF cannot animate"
        )
    # Unweighted, unanimated roots (an "Armature" node with a 100x scale, a scene root) become
    # plain nodes above the skin, as in the files they came from: Blender then makes them the
    # armature object instead of bones, which cannot hold a rest scale.
    weighted = asset.skin_weights_dense().sum(0) > 0
    plain = np.zeros(J, bool)
    for j, p in enumerate(asset.parents):
        plain[j] = not weighted[j] and not animated[j] and not must_key[j] and (p < 0 or plain[p])
    skin_joints = np.nonzero(~plain)[0]
    skin_index = np.full(J, -1)
    skin_index[skin_joints] = np.arange(len(skin_joints))
    animated = np.nonzero(animated)[0]

    nodes: list[dict[str, Any]] = []
    for j in range(J):
        node: dict[str, Any] = {"name": asset.joint_names[j]}
        if exact[j]:
            if np.abs(t[j]).max() > 0:
                node["translation"] = t[j].tolist()
            if np.abs(q[j] - [1, 0, 0, 0]).max() > 0:
                node["rotation"] = [float(q[j][1]), float(q[j][2]), float(q[j][3]), float(q[j][0])]
            if np.abs(s[j] - 1).max() > 0:
                node["scale"] = s[j].tolist()
        else:
            node["matrix"] = node_local[j].T.reshape(-1).tolist()
        children = np.nonzero(asset.parents == j)[0]
        if len(children):
            node["children"] = [int(c) for c in children]
        nodes.append(node)

    V = asset.num_vertices
    attrs = {
        "POSITION": b.accessor(asset.vertices, _FLOAT, _ARRAY_BUFFER, minmax=True),
        "NORMAL": b.accessor(_vertex_normals(asset.vertices, asset.faces), _FLOAT, _ARRAY_BUFFER),
    }
    K = asset.skin_joints.shape[1]
    sets = (K + 3) // 4
    sj = np.zeros((V, 4 * sets), np.int64)
    sw = np.zeros((V, 4 * sets), np.float32)
    sj[:, :K], sw[:, :K] = skin_index[asset.skin_joints], asset.skin_weights
    sj[sw == 0] = 0  # unused influences point at skin joint 0 with weight 0
    jtype = _UINT8 if len(skin_joints) <= 256 else _UINT16
    for k in range(sets):
        attrs[f"JOINTS_{k}"] = b.accessor(sj[:, 4 * k : 4 * k + 4], jtype, _ARRAY_BUFFER)
        attrs[f"WEIGHTS_{k}"] = b.accessor(sw[:, 4 * k : 4 * k + 4], _FLOAT, _ARRAY_BUFFER)
    if asset.vertex_colors is not None:
        attrs["COLOR_0"] = b.accessor(asset.vertex_colors, _FLOAT, _ARRAY_BUFFER)
    if asset.uvs is not None:
        attrs["TEXCOORD_0"] = b.accessor(asset.uvs, _FLOAT, _ARRAY_BUFFER)
    itype = _UINT16 if V < 65535 else _UINT32
    indices = b.accessor(asset.faces.reshape(-1), itype, _ELEMENT_ARRAY_BUFFER)

    pbr: dict[str, Any] = {
        "baseColorFactor": [1.0, 1.0, 1.0, 1.0],
        "metallicFactor": 0.0,
        "roughnessFactor": 0.8,
    }
    doc: dict[str, Any] = {
        "asset": {"version": "2.0", "generator": "zooctl"},
        "scene": 0,
        "scenes": [{"name": asset.name, "nodes": [int(j) for j in np.nonzero(asset.parents < 0)[0]] + [J]}],
        "nodes": nodes,
        "meshes": [
            {
                "name": asset.name,
                "primitives": [{"attributes": attrs, "indices": indices, "material": 0, "mode": 4}],
            }
        ],
        "materials": [{"name": f"{asset.name}_material", "pbrMetallicRoughness": pbr}],
        "skins": [
            {
                "name": asset.name,
                "joints": [int(j) for j in skin_joints],
                "inverseBindMatrices": b.accessor(
                    asset.inverse_bind[skin_joints].transpose(0, 2, 1).reshape(-1, 16), _FLOAT
                ),
            }
        ],
    }
    nodes.append({"name": f"{asset.name}_mesh", "mesh": 0, "skin": 0})
    if asset.texture_png is not None and asset.uvs is not None:
        doc["images"] = [{"bufferView": b.view(asset.texture_png), "mimeType": "image/png"}]
        doc["samplers"] = [{"magFilter": 9729, "minFilter": 9987, "wrapS": 10497, "wrapT": 10497}]
        doc["textures"] = [{"source": 0, "sampler": 0}]
        pbr["baseColorTexture"] = {"index": 0, "texCoord": 0}
    extras = {
        k: asset.meta[k] for k in ("license", "source", "tags", "meters_per_unit", "label") if k in asset.meta
    }
    if extras:
        doc["asset"]["extras"] = extras

    animations = []
    for name in names:
        c = asset.clips[name]
        joints = animated
        times = b.accessor(_frame_times(c.num_frames, c.fps), _FLOAT, minmax=True)
        rot = _continuous(c.rotations[:, joints])[..., [1, 2, 3, 0]]  # wxyz -> xyzw
        samplers, channels = [], []
        for i, j in enumerate(joints):
            for path, values in (
                ("translation", c.translations[:, j]),
                ("rotation", rot[:, i]),
                ("scale", c.scales[:, j]),
            ):
                samplers.append(
                    {"input": times, "output": b.accessor(values, _FLOAT), "interpolation": "LINEAR"}
                )
                channels.append({"sampler": len(samplers) - 1, "target": {"node": int(j), "path": path}})
        animations.append({"name": name, "samplers": samplers, "channels": channels})
    if animations:
        doc["animations"] = animations
    doc["accessors"] = b.accessors
    doc["bufferViews"] = b.views
    doc["buffers"] = [{"byteLength": len(b.blob)}]
    return doc, bytes(b.blob)


def glb_bytes(doc: dict[str, Any], blob: bytes) -> bytes:
    """Pack a document and its buffer as GLB: 12-byte header, JSON chunk, BIN chunk."""
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    bin_ = blob + b"\0" * (-len(blob) % 4)
    total = 12 + 8 + len(js) + 8 + len(bin_)
    return b"".join(
        [
            struct.pack("<III", 0x46546C67, 2, total),
            struct.pack("<II", len(js), 0x4E4F534A),
            js,
            struct.pack("<II", len(bin_), 0x004E4942),
            bin_,
        ]
    )


def save_glb(asset: RiggedAsset, path: str | Path, clips: Sequence[str] | None = None) -> Path:
    """Write ``asset`` (and the named clips, or all) as a ``.glb`` file, atomically."""
    path = Path(path)
    if path.suffix.lower() != ".glb":
        raise UsageError(f"cannot write glTF binary to {path.name!r}", hint="use a .glb file name")
    doc, blob = gltf_document(asset, clips)
    write_bytes_atomic(path, glb_bytes(doc, blob))
    return path
