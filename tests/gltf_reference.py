"""An independent glTF 2.0 skinning reader, written from the spec for the import tests.

It shares no code with `zooctl.io.gltf_import`: it evaluates the node hierarchy with every node
animated at time t (scipy's Slerp for rotations) and skins each mesh node with
``world(joint) @ inverseBindMatrix @ v`` directly on glTF's node indices.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

DT = {5120: "i1", 5121: "u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
NC = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


class Reference:
    def __init__(self, path: Path):
        data = path.read_bytes()
        jlen = struct.unpack("<I", data[12:16])[0]
        self.g = json.loads(data[20 : 20 + jlen])
        blen = struct.unpack("<I", data[20 + jlen : 24 + jlen])[0]
        self.bin = data[28 + jlen : 28 + jlen + blen]
        self.parent = {c: i for i, n in enumerate(self.g["nodes"]) for c in n.get("children", [])}

    def acc(self, i: int) -> np.ndarray:
        a = self.g["accessors"][i]
        bv = self.g["bufferViews"][a["bufferView"]]
        dt = np.dtype(DT[a["componentType"]])
        n = NC[a["type"]]
        stride = bv.get("byteStride", dt.itemsize * n)
        start = bv.get("byteOffset", 0) + a.get("byteOffset", 0)
        raw = np.frombuffer(self.bin, np.uint8)
        idx = start + np.arange(a["count"])[:, None] * stride + np.arange(n * dt.itemsize)[None]
        out = raw[idx].copy().view(dt).reshape(a["count"], n).astype(np.float64)
        if a.get("normalized"):
            out = out / np.iinfo(dt).max
        return out

    def node_trs(self, i: int, anim: dict | None, t: float):
        n = self.g["nodes"][i]
        T = np.array(n.get("translation", [0, 0, 0]), float)
        R = np.array(n.get("rotation", [0, 0, 0, 1]), float)  # xyzw, scipy's order
        S = np.array(n.get("scale", [1, 1, 1]), float)
        if anim is not None:
            for ch in anim["channels"]:
                if ch["target"].get("node") != i:
                    continue
                s = anim["samplers"][ch["sampler"]]
                times = self.acc(s["input"])[:, 0]
                vals = self.acc(s["output"])
                path = ch["target"]["path"]
                tt = float(np.clip(t, times[0], times[-1]))
                if path == "rotation":
                    R = Slerp(times, Rotation.from_quat(vals))(tt).as_quat() if len(times) > 1 else vals[0]
                elif path in ("translation", "scale"):
                    v = np.array([np.interp(tt, times, vals[:, c]) for c in range(3)])
                    if path == "translation":
                        T = v
                    else:
                        S = v
        M = np.eye(4)
        M[:3, :3] = Rotation.from_quat(R).as_matrix() @ np.diag(S)
        M[:3, 3] = T
        if "matrix" in n:
            M = np.array(n["matrix"], float).reshape(4, 4).T
        return M

    def world(self, anim: dict | None, t: float) -> list[np.ndarray]:
        cache: dict[int, np.ndarray] = {}

        def w(i: int) -> np.ndarray:
            if i not in cache:
                local = self.node_trs(i, anim, t)
                cache[i] = w(self.parent[i]) @ local if i in self.parent else local
            return cache[i]

        return [w(i) for i in range(len(self.g["nodes"]))]

    def anim_start(self, anim: dict) -> float:
        return min(self.acc(anim["samplers"][c["sampler"]]["input"])[0, 0] for c in anim["channels"])

    def skinned_vertices(self, anim_name: str | None, t: float) -> np.ndarray:
        anim = None
        if anim_name is not None:
            anim = next(a for a in self.g["animations"] if a.get("name") == anim_name)
        W = self.world(anim, t)
        out = []
        for n in self.g["nodes"]:
            if "mesh" not in n or "skin" not in n:
                continue
            skin = self.g["skins"][n["skin"]]
            ibm = self.acc(skin["inverseBindMatrices"]).reshape(-1, 4, 4).transpose(0, 2, 1)
            mats = np.array([W[j] @ ibm[k] for k, j in enumerate(skin["joints"])])
            for p in self.g["meshes"][n["mesh"]]["primitives"]:
                v = self.acc(p["attributes"]["POSITION"])
                jj = self.acc(p["attributes"]["JOINTS_0"]).astype(int)
                ww = self.acc(p["attributes"]["WEIGHTS_0"])
                ww = ww / ww.sum(1, keepdims=True)
                vh = np.c_[v, np.ones(len(v))]
                pos = np.zeros((len(v), 3))
                for k in range(jj.shape[1]):
                    pos += ww[:, k : k + 1] * np.einsum("vij,vj->vi", mats[jj[:, k]], vh)[:, :3]
                out.append(pos)
        return np.concatenate(out)
