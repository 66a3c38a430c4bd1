"""glTF 2.0 import (``.glb``, and ``.gltf`` with external or embedded buffers and images).

What becomes of a file:

- Every triangle primitive of every mesh node bound to a skin is merged into one mesh. When a file
  has several skins, their joints are united; a skin whose inverse bind matrices differ from the
  first one's by a common transform gets its vertices moved by that transform.
- Mesh nodes *without* a skin that hang below a joint (eyes, horns, armour) are bound rigidly to
  that joint with weight 1. Unskinned meshes elsewhere are ignored.
- The skeleton is every skin joint plus every ancestor node of one (an ``Armature`` node's
  transform is part of the joints' world transforms), topologically sorted. Ancestors that are not
  skin joints get inverse bind matrices from their rest pose and no skin weights.
- JOINTS_0/WEIGHTS_0 and JOINTS_1/WEIGHTS_1 are read (up to 8 influences), renormalised to sum 1.
- Each animation becomes a `Clip` sampled at ``fps`` (LINEAR with slerp for rotations, STEP,
  CUBICSPLINE); channels on nodes outside the skeleton and morph-target weights are ignored.
- Vertex colours come from COLOR_0 times the material's baseColorFactor; a single shared
  baseColorTexture is kept with TEXCOORD_0.
"""

from __future__ import annotations

import base64
import io
import json
import struct
from pathlib import Path
from typing import Any

import numpy as np

from ..asset import Clip, RiggedAsset
from ..errors import InputError
from ..geometry import compose_trs, decompose_trs, quat_normalize, quat_slerp

GLB_MAGIC = 0x46546C67
_COMPONENT = {
    5120: np.int8,
    5121: np.uint8,
    5122: np.int16,
    5123: np.uint16,
    5125: np.uint32,
    5126: np.float32,
}
_NCOMP = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
MAX_INFLUENCES = 8


class _Doc:
    """A parsed glTF document with its buffers, read lazily."""

    def __init__(self, path: Path):
        self.path = path
        self.base = path.parent
        data = _read_bytes(path)
        self.glb_bin: bytes | None = None
        if path.suffix.lower() == ".glb" or data[:4] == b"glTF":
            self.json, self.glb_bin = _parse_glb(path, data)
        else:
            try:
                self.json = json.loads(data.decode("utf-8"))
            except (UnicodeDecodeError, json.JSONDecodeError) as exc:
                raise InputError(f"{path}: not a glTF JSON file ({exc})") from None
        if not isinstance(self.json, dict) or "asset" not in self.json:
            raise InputError(f"{path}: not a glTF 2.0 document (no 'asset' object)")
        version = str(self.json["asset"].get("version", ""))
        if not version.startswith("2"):
            raise InputError(
                f"{path}: glTF version {version!r} is not supported", hint="convert it to glTF 2.0"
            )
        self._buffers: dict[int, bytes] = {}

    def get(self, key: str) -> list[dict[str, Any]]:
        v = self.json.get(key, [])
        return v if isinstance(v, list) else []

    def buffer(self, i: int) -> bytes:
        if i not in self._buffers:
            buffers = self.get("buffers")
            if i >= len(buffers):
                raise InputError(f"{self.path}: buffer {i} does not exist")
            b = buffers[i]
            uri = b.get("uri")
            if uri is None:
                if self.glb_bin is None:
                    raise InputError(f"{self.path}: buffer {i} has no uri and there is no GLB binary chunk")
                data = self.glb_bin
            else:
                data = self._uri(uri, f"buffer {i}")
            if len(data) < int(b.get("byteLength", 0)):
                raise InputError(
                    f"{self.path}: buffer {i} is truncated ({len(data)} of {b.get('byteLength')} bytes)",
                    hint="the file was cut short; re-export or re-download it",
                )
            self._buffers[i] = data
        return self._buffers[i]

    def _uri(self, uri: str, what: str) -> bytes:
        if uri.startswith("data:"):
            try:
                return base64.b64decode(uri.split(",", 1)[1])
            except Exception:
                raise InputError(f"{self.path}: {what} has a malformed data URI") from None
        from urllib.parse import unquote

        p = self.base / unquote(uri)
        if not p.is_file():
            raise InputError(
                f"{self.path}: {what} refers to {uri!r}, which is missing",
                hint=f"put {uri} next to {self.path.name}, or export a self-contained .glb",
            )
        return p.read_bytes()

    def view_bytes(self, vi: int) -> tuple[bytes, int, int | None]:
        views = self.get("bufferViews")
        if vi >= len(views):
            raise InputError(f"{self.path}: bufferView {vi} does not exist")
        v = views[vi]
        buf = self.buffer(int(v["buffer"]))
        off = int(v.get("byteOffset", 0))
        length = int(v["byteLength"])
        if off + length > len(buf):
            raise InputError(
                f"{self.path}: bufferView {vi} runs past the end of its buffer (truncated file?)"
            )
        return buf, off, v.get("byteStride")

    def accessor(self, ai: int) -> np.ndarray:
        accs = self.get("accessors")
        if not isinstance(ai, int) or ai >= len(accs):
            raise InputError(f"{self.path}: accessor {ai} does not exist")
        a = accs[ai]
        dtype = np.dtype(
            _COMPONENT.get(a.get("componentType"), None) or _bad(self.path, f"accessor {ai} component type")
        )
        nc = _NCOMP.get(a.get("type"), 0) or _bad(self.path, f"accessor {ai} type")
        count = int(a["count"])
        if "bufferView" in a:
            buf, off, stride = self.view_bytes(int(a["bufferView"]))
            off += int(a.get("byteOffset", 0))
            elem = dtype.itemsize * nc
            stride = int(stride or elem)
            need = off + stride * (count - 1) + elem if count else off
            if need > len(buf):
                raise InputError(
                    f"{self.path}: accessor {ai} runs past the end of its buffer (truncated file?)"
                )
            if stride == elem:
                out = np.frombuffer(buf, dtype=dtype, count=count * nc, offset=off).reshape(count, nc).copy()
            else:
                raw = np.frombuffer(buf, dtype=np.uint8, count=stride * (count - 1) + elem, offset=off)
                rows = np.lib.stride_tricks.as_strided(raw, shape=(count, elem), strides=(stride, 1))
                out = rows.copy().view(dtype).reshape(count, nc)
        else:
            out = np.zeros((count, nc), dtype=dtype)
        sparse = a.get("sparse")
        if sparse:
            n = int(sparse["count"])
            idx_info, val_info = sparse["indices"], sparse["values"]
            ib, io_, _ = self.view_bytes(int(idx_info["bufferView"]))
            idx = np.frombuffer(
                ib,
                dtype=_COMPONENT[idx_info["componentType"]],
                count=n,
                offset=io_ + int(idx_info.get("byteOffset", 0)),
            )
            vb, vo, _ = self.view_bytes(int(val_info["bufferView"]))
            vals = np.frombuffer(
                vb, dtype=dtype, count=n * nc, offset=vo + int(val_info.get("byteOffset", 0))
            ).reshape(n, nc)
            out = out.copy()
            if idx.size and idx.max() >= count:
                raise InputError(f"{self.path}: sparse accessor {ai} has indices out of range")
            out[idx.astype(np.int64)] = vals
        if a.get("normalized") and dtype.kind in "iu":
            info = np.iinfo(dtype)
            out = np.maximum(out.astype(np.float64) / info.max, -1.0)
        return out

    def image_bytes(self, ii: int) -> bytes | None:
        images = self.get("images")
        if ii >= len(images):
            return None
        im = images[ii]
        if "bufferView" in im:
            buf, off, _ = self.view_bytes(int(im["bufferView"]))
            length = int(self.get("bufferViews")[int(im["bufferView"])]["byteLength"])
            return bytes(buf[off : off + length])
        if "uri" in im:
            return self._uri(im["uri"], f"image {ii}")
        return None


def _bad(path: Path, what: str) -> Any:
    raise InputError(f"{path}: invalid {what}")


def _read_bytes(path: Path) -> bytes:
    if path.is_dir():
        raise InputError(f"{path} is a directory", hint="give a .glb or .gltf file")
    if not path.exists():
        raise InputError(f"{path} does not exist")
    data = path.read_bytes()
    if not data:
        raise InputError(f"{path} is empty")
    return data


def _parse_glb(path: Path, data: bytes) -> tuple[dict[str, Any], bytes | None]:
    if len(data) < 20:
        raise InputError(f"{path}: truncated GLB (only {len(data)} bytes)")
    magic, version, length = struct.unpack_from("<III", data, 0)
    if magic != GLB_MAGIC:
        raise InputError(f"{path}: not a GLB file (bad magic)")
    if version != 2:
        raise InputError(f"{path}: GLB container version {version} is not supported")
    if length > len(data):
        raise InputError(
            f"{path}: truncated GLB ({len(data)} of {length} bytes)",
            hint="the file was cut short; re-export or re-download it",
        )
    off = 12
    js: dict[str, Any] | None = None
    binary: bytes | None = None
    while off + 8 <= length:
        clen, ctype = struct.unpack_from("<II", data, off)
        chunk = data[off + 8 : off + 8 + clen]
        if len(chunk) < clen:
            raise InputError(f"{path}: truncated GLB chunk")
        if ctype == 0x4E4F534A:
            try:
                js = json.loads(chunk.decode("utf-8"))
            except (UnicodeDecodeError, json.JSONDecodeError) as exc:
                raise InputError(f"{path}: GLB JSON chunk is malformed ({exc})") from None
        elif ctype == 0x004E4942 and binary is None:
            binary = chunk
        off += 8 + clen
    if js is None:
        raise InputError(f"{path}: GLB has no JSON chunk")
    return js, binary


def _node_local(node: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rest TRS of a node (from its matrix when it has one)."""
    if "matrix" in node:
        m = np.asarray(node["matrix"], dtype=np.float64).reshape(4, 4).T  # glTF stores column-major
        return decompose_trs(m)
    t = np.asarray(node.get("translation", [0, 0, 0]), dtype=np.float64)
    x, y, z, w = node.get("rotation", [0, 0, 0, 1])
    q = quat_normalize(np.array([w, x, y, z], dtype=np.float64))
    s = np.asarray(node.get("scale", [1, 1, 1]), dtype=np.float64)
    return t, q, s


def _triangles(doc: _Doc, prim: dict[str, Any], nverts: int) -> np.ndarray:
    mode = prim.get("mode", 4)
    if "indices" in prim:
        idx = doc.accessor(prim["indices"]).reshape(-1).astype(np.int64)
    else:
        idx = np.arange(nverts, dtype=np.int64)
    if mode == 4:
        tris = idx[: len(idx) // 3 * 3].reshape(-1, 3)
    elif mode == 5:  # strip: alternate winding
        tris = np.array(
            [
                (idx[i], idx[i + 1], idx[i + 2]) if i % 2 == 0 else (idx[i + 1], idx[i], idx[i + 2])
                for i in range(len(idx) - 2)
            ]
        )
    elif mode == 6:  # fan
        tris = np.array([(idx[0], idx[i], idx[i + 1]) for i in range(1, len(idx) - 1)])
    else:
        return np.zeros((0, 3), dtype=np.int64)
    tris = tris.reshape(-1, 3)
    if tris.size and (tris.min() < 0 or tris.max() >= nverts):
        raise InputError(f"{doc.path}: triangle indices out of range of the {nverts} vertices")
    return tris


def load_gltf(path: str | Path, name: str, fps: float = 30.0) -> RiggedAsset:
    """Import a glTF 2.0 file as a validated `RiggedAsset` (see the module docstring)."""
    path = Path(path)
    doc = _Doc(path)
    nodes = doc.get("nodes")
    skins = doc.get("skins")
    if not skins:
        raise InputError(
            f"{path}: the file has no skin (no rigged mesh)", hint="zooctl needs a skinned, rigged mesh"
        )
    parent = np.full(len(nodes), -1, dtype=np.int64)
    for i, n in enumerate(nodes):
        for c in n.get("children", []):
            if not (0 <= c < len(nodes)) or parent[c] != -1:
                raise InputError(f"{path}: node hierarchy is not a tree (node {c})")
            parent[c] = i
    rest = [_node_local(n) for n in nodes]
    rest_m = (
        compose_trs(
            np.array([r[0] for r in rest]), np.array([r[1] for r in rest]), np.array([r[2] for r in rest])
        )
        if nodes
        else np.zeros((0, 4, 4))
    )
    world = _world(rest_m, parent)

    skinned = [(i, n) for i, n in enumerate(nodes) if "mesh" in n and "skin" in n]
    if not skinned:
        raise InputError(
            f"{path}: no mesh node is bound to a skin", hint="zooctl needs a skinned, rigged mesh"
        )
    used_skins = sorted({int(n["skin"]) for _, n in skinned})
    for s in used_skins:
        if s >= len(skins):
            raise InputError(f"{path}: a mesh refers to skin {s}, which does not exist")

    # Skeleton = skin joints of the used skins plus all their ancestors, in depth-first order.
    joint_nodes: set[int] = set()
    for s in used_skins:
        for j in skins[s]["joints"]:
            if not (0 <= j < len(nodes)):
                raise InputError(f"{path}: skin {s} names node {j}, which does not exist")
            joint_nodes.add(int(j))
    keep = set(joint_nodes)
    for j in list(joint_nodes):
        p = parent[j]
        while p >= 0:
            keep.add(int(p))
            p = parent[p]
    order: list[int] = []
    stack = sorted((i for i in keep if parent[i] < 0 or parent[i] not in keep), reverse=True)
    while stack:
        i = stack.pop()
        order.append(i)
        stack.extend(reversed([c for c in nodes[i].get("children", []) if c in keep]))
    node_to_joint = {n: k for k, n in enumerate(order)}
    J = len(order)
    parents = np.array([node_to_joint.get(int(parent[n]), -1) for n in order], dtype=np.int32)
    names = _unique_names([nodes[n].get("name") or f"node{n}" for n in order])
    rest_local = rest_m[order]
    ibm = np.linalg.inv(world[order])  # default for non-joint ancestors
    ibm_skin: dict[int, np.ndarray] = {}
    for s in used_skins:
        sk = skins[s]
        m = (
            doc.accessor(sk["inverseBindMatrices"]).reshape(-1, 4, 4).transpose(0, 2, 1).astype(np.float64)
            if "inverseBindMatrices" in sk
            else np.tile(np.eye(4), (len(sk["joints"]), 1, 1))
        )
        if m.shape[0] != len(sk["joints"]):
            raise InputError(
                f"{path}: skin {s} has {m.shape[0]} inverse bind matrices for {len(sk['joints'])} joints"
            )
        ibm_skin[s] = m
    first = used_skins[0]
    assigned = np.zeros(J, dtype=bool)
    for s in [first] + used_skins[1:]:
        for k, j in enumerate(skins[s]["joints"]):
            jj = node_to_joint[int(j)]
            if not assigned[jj]:
                ibm[jj] = ibm_skin[s][k]
                assigned[jj] = True

    verts, faces, sj, sw, cols, uvs, tex_ids = [], [], [], [], [], [], []
    warnings: list[str] = []
    offset = 0
    meshes = doc.get("meshes")
    materials = doc.get("materials")
    for node_i, node in skinned:
        s = int(node["skin"])
        skin_joints = np.array([node_to_joint[int(j)] for j in skins[s]["joints"]], dtype=np.int64)
        # A skin whose bind matrices differ from the canonical ones by one transform M gets v -> M v.
        fix = np.linalg.inv(ibm[skin_joints]) @ ibm_skin[s]
        if not np.allclose(fix, fix[:1], atol=1e-4 * max(1.0, float(np.abs(fix).max()))):
            raise InputError(f"{path}: skins {first} and {s} bind the same joints inconsistently")
        M = fix[0]
        for prim in _mesh(doc, meshes, node["mesh"])["primitives"]:
            got = _primitive(doc, prim, materials)
            if got is None:
                continue
            v, f, col, uv, tex = got
            attrs = prim["attributes"]
            if "JOINTS_0" not in attrs or "WEIGHTS_0" not in attrs:
                raise InputError(
                    f"{path}: a primitive of skinned mesh {node.get('name', node_i)!r} has no JOINTS_0/WEIGHTS_0"
                )
            js = [doc.accessor(attrs["JOINTS_0"])]
            ws = [doc.accessor(attrs["WEIGHTS_0"]).astype(np.float64)]
            if "JOINTS_1" in attrs and "WEIGHTS_1" in attrs:
                js.append(doc.accessor(attrs["JOINTS_1"]))
                ws.append(doc.accessor(attrs["WEIGHTS_1"]).astype(np.float64))
            jj = np.concatenate(js, 1).astype(np.int64)
            ww = np.concatenate(ws, 1)
            if jj.shape[0] != v.shape[0] or ww.shape[0] != v.shape[0]:
                raise InputError(f"{path}: skin attribute counts do not match the vertex count")
            ww = _repair_unweighted(path, v, jj, ww, warnings)
            if np.any(ww < 0):
                raise InputError(f"{path}: skin weights are negative")
            if np.any(jj[ww > 0] >= len(skin_joints)) or np.any(jj < 0):
                raise InputError(
                    f"{path}: joint indices out of range of skin {s}'s {len(skin_joints)} joints"
                )
            jj = skin_joints[np.clip(jj, 0, len(skin_joints) - 1)]
            if not np.allclose(M, np.eye(4), atol=1e-6):
                v = v @ M[:3, :3].T + M[:3, 3]
            verts.append(v)
            faces.append(f + offset)
            sj.append(jj)
            sw.append(ww)
            cols.append(col)
            uvs.append(uv)
            tex_ids.append(tex)
            offset += v.shape[0]

    # Rigid attachments: unskinned meshes under a joint follow that joint with weight 1.
    for i, node in enumerate(nodes):
        if "mesh" not in node or "skin" in node:
            continue
        p = int(parent[i])
        while p >= 0 and p not in node_to_joint:
            p = int(parent[p])
        if p < 0:
            continue
        jj_i = node_to_joint[p]
        to_bind = np.linalg.inv(ibm[jj_i]) @ np.linalg.inv(world[p]) @ world[i]
        for prim in _mesh(doc, meshes, node["mesh"])["primitives"]:
            got = _primitive(doc, prim, materials)
            if got is None:
                continue
            v, f, col, uv, tex = got
            v = v @ to_bind[:3, :3].T + to_bind[:3, 3]
            verts.append(v)
            faces.append(f + offset)
            sj.append(np.full((v.shape[0], 1), jj_i, dtype=np.int64))
            sw.append(np.ones((v.shape[0], 1)))
            cols.append(col)
            uvs.append(uv)
            tex_ids.append(tex)
            offset += v.shape[0]

    if not verts:
        raise InputError(f"{path}: the skinned meshes have no triangles")
    K = max(x.shape[1] for x in sj)
    sj = [np.pad(x, ((0, 0), (0, K - x.shape[1]))) for x in sj]
    sw = [np.pad(x, ((0, 0), (0, K - x.shape[1]))) for x in sw]
    joints_all = np.concatenate(sj)
    weights_all = np.concatenate(sw)
    total = weights_all.sum(1)
    if np.any(total <= 0):
        raise InputError(f"{path}: {(total <= 0).sum()} vertices have no skin weight")
    weights_all = weights_all / total[:, None]
    order_k = np.argsort(-weights_all, axis=1, kind="stable")
    weights_all = np.take_along_axis(weights_all, order_k, 1)
    joints_all = np.take_along_axis(joints_all, order_k, 1)
    keep_k = max(1, int((weights_all > 0).any(0).sum()))
    joints_all, weights_all = joints_all[:, :keep_k], weights_all[:, :keep_k]
    joints_all[weights_all == 0] = 0

    vertex_colors = np.concatenate(cols).astype(np.float32)
    uv_all = None
    texture = None
    distinct_tex = {t for t in tex_ids if t is not None}
    if len(distinct_tex) == 1 and all(u is not None for u in uvs):
        uv_all = np.concatenate(uvs).astype(np.float32)
        texture = _texture_png(doc, distinct_tex.pop())
        if texture is None:
            uv_all = None

    clips = _clips(doc, nodes, node_to_joint, rest, order, fps)
    asset = RiggedAsset(
        name=name,
        vertices=np.concatenate(verts).astype(np.float32),
        faces=np.concatenate(faces).astype(np.int32),
        joint_names=names,
        parents=parents,
        rest_local=rest_local,
        inverse_bind=ibm,
        skin_joints=joints_all.astype(np.int32),
        skin_weights=weights_all.astype(np.float32),
        clips=clips,
        uvs=uv_all,
        vertex_colors=vertex_colors,
        texture_png=texture,
        meta={
            "source": str(path),
            "source_format": "gltf",
            "units": "m",
            "meters_per_unit": 1.0,
            "up_axis": "Y",
            "generator": str(doc.json.get("asset", {}).get("generator", "")),
            "license": str(doc.json.get("asset", {}).get("copyright", "")),
            "import_warnings": warnings,
        },
    )
    return asset.validate()


MAX_REPAIRED_FRACTION = 0.05


def _repair_unweighted(
    path: Path, v: np.ndarray, jj: np.ndarray, ww: np.ndarray, warnings: list[str]
) -> np.ndarray:
    """Vertices whose weights are all NaN or all zero get the weights of their nearest weighted
    vertex: real exporters leave a handful of these (Quaternius' Wasp has 6). More than 5% of a
    primitive, or NaN mixed into otherwise valid rows, is an error."""
    finite = np.isfinite(ww)
    row_bad = ~finite.all(1)
    if np.any(row_bad & finite.any(1)):
        raise InputError(
            f"{path}: skin weights contain NaN or infinity", hint="fix the weights in the source file"
        )
    dead = row_bad | (np.where(finite, ww, 0).sum(1) <= 0)
    if not dead.any():
        return ww
    if dead.mean() > MAX_REPAIRED_FRACTION or dead.all():
        what = "NaN or infinite" if row_bad.any() else "zero"
        raise InputError(
            f"{path}: {int(dead.sum())} of {len(ww)} vertices have {what} skin weights",
            hint="fix the weights in the source file",
        )
    from scipy.spatial import cKDTree

    good = np.flatnonzero(~dead)
    _, nn = cKDTree(v[good]).query(v[dead])
    ww = ww.copy()
    ww[dead] = ww[good[nn]]
    jj[dead] = jj[good[nn]]
    warnings.append(
        f"{int(dead.sum())} vertices had no valid skin weights; copied from their nearest neighbours"
    )
    return ww


def _mesh(doc: _Doc, meshes: list[dict[str, Any]], mi: int) -> dict[str, Any]:
    if not (0 <= mi < len(meshes)):
        raise InputError(f"{doc.path}: mesh {mi} does not exist")
    return meshes[mi]


def _primitive(doc: _Doc, prim: dict[str, Any], materials: list[dict[str, Any]]):
    attrs = prim.get("attributes", {})
    if "POSITION" not in attrs or prim.get("mode", 4) not in (4, 5, 6):
        return None
    v = doc.accessor(attrs["POSITION"]).astype(np.float64)
    if v.shape[1] != 3:
        raise InputError(f"{doc.path}: POSITION must be VEC3")
    if not np.all(np.isfinite(v)):
        raise InputError(f"{doc.path}: vertex positions contain NaN or infinity")
    f = _triangles(doc, prim, v.shape[0])
    mat = materials[prim["material"]] if "material" in prim and prim["material"] < len(materials) else {}
    pbr = mat.get("pbrMetallicRoughness", {})
    base = np.asarray(pbr.get("baseColorFactor", [1, 1, 1, 1]), dtype=np.float64)[:3]
    col = np.tile(base, (v.shape[0], 1))
    if "COLOR_0" in attrs:
        c = doc.accessor(attrs["COLOR_0"]).astype(np.float64)
        col = col * c[:, :3]
    uv = doc.accessor(attrs["TEXCOORD_0"]).astype(np.float64) if "TEXCOORD_0" in attrs else None
    tex = pbr.get("baseColorTexture", {}).get("index")
    return v, f, np.clip(col, 0, 1), uv, tex


def _texture_png(doc: _Doc, tex_index: int) -> bytes | None:
    textures = doc.get("textures")
    if tex_index >= len(textures) or "source" not in textures[tex_index]:
        return None
    data = doc.image_bytes(int(textures[tex_index]["source"]))
    if data is None:
        return None
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        return data
    try:
        from PIL import Image

        buf = io.BytesIO()
        Image.open(io.BytesIO(data)).convert("RGBA").save(buf, format="PNG")
        return buf.getvalue()
    except Exception:
        return None


def _unique_names(names: list[str]) -> list[str]:
    seen: dict[str, int] = {}
    out = []
    for n in names:
        if n in seen:
            seen[n] += 1
            n = f"{n}.{seen[n]}"
        seen.setdefault(n, 0)
        out.append(n)
    return out


def _world(local: np.ndarray, parent: np.ndarray) -> np.ndarray:
    out = np.empty_like(local)
    done = np.zeros(len(local), dtype=bool)

    def visit(i: int) -> None:
        if done[i]:
            return
        p = parent[i]
        if p >= 0:
            visit(int(p))
            out[i] = out[p] @ local[i]
        else:
            out[i] = local[i]
        done[i] = True

    for i in range(len(local)):
        visit(i)
    return out


def _sample(times: np.ndarray, values: np.ndarray, interp: str, t: np.ndarray, is_rot: bool) -> np.ndarray:
    """Sample one channel at times t. values: (K, C) or (3K, C) for CUBICSPLINE."""
    K = times.shape[0]
    if interp == "CUBICSPLINE":
        vals = values.reshape(K, 3, -1)
        a_in, v, b_out = vals[:, 0], vals[:, 1], vals[:, 2]
    else:
        v = values
    if K == 1:
        out = np.repeat(v[:1], len(t), 0)
        return quat_normalize(out) if is_rot else out
    i = np.clip(np.searchsorted(times, t, side="right") - 1, 0, K - 2)
    t0, t1 = times[i], times[i + 1]
    dt = np.maximum(t1 - t0, 1e-12)
    u = np.clip((t - t0) / dt, 0.0, 1.0)
    if interp == "STEP":
        out = np.where((u >= 1.0)[:, None], v[i + 1], v[i])
    elif interp == "CUBICSPLINE":
        u2, u3 = u * u, u * u * u
        h00 = 2 * u3 - 3 * u2 + 1
        h10 = u3 - 2 * u2 + u
        h01 = -2 * u3 + 3 * u2
        h11 = u3 - u2
        out = (
            h00[:, None] * v[i]
            + (h10 * dt)[:, None] * b_out[i]
            + h01[:, None] * v[i + 1]
            + (h11 * dt)[:, None] * a_in[i + 1]
        )
    elif is_rot:
        out = quat_slerp(v[i], v[i + 1], u)
    else:
        out = v[i] * (1 - u)[:, None] + v[i + 1] * u[:, None]
    return quat_normalize(out) if is_rot else out


def _clips(doc: _Doc, nodes, node_to_joint, rest, order, fps: float) -> dict[str, Clip]:
    clips: dict[str, Clip] = {}
    rest_t = np.array([rest[n][0] for n in order])
    rest_q = np.array([rest[n][1] for n in order])
    rest_s = np.array([rest[n][2] for n in order])
    for ai, anim in enumerate(doc.get("animations")):
        samplers = anim.get("samplers", [])
        chans = []
        t_lo, t_hi = np.inf, -np.inf
        for ch in anim.get("channels", []):
            tgt = ch.get("target", {})
            node, prop = tgt.get("node"), tgt.get("path")
            if node not in node_to_joint or prop not in ("translation", "rotation", "scale"):
                continue
            si = ch.get("sampler")
            if not isinstance(si, int) or si >= len(samplers):
                raise InputError(f"{doc.path}: animation {ai} refers to a missing sampler")
            smp = samplers[si]
            times = doc.accessor(smp["input"]).reshape(-1).astype(np.float64)
            vals = doc.accessor(smp["output"]).astype(np.float64)
            if times.size == 0:
                continue
            if not (np.all(np.isfinite(times)) and np.all(np.isfinite(vals))):
                raise InputError(f"{doc.path}: animation {ai} contains NaN or infinity")
            interp = smp.get("interpolation", "LINEAR")
            if interp not in ("LINEAR", "STEP", "CUBICSPLINE"):
                raise InputError(f"{doc.path}: animation {ai} uses unknown interpolation {interp!r}")
            if prop == "rotation":
                vals = vals[:, [3, 0, 1, 2]]  # xyzw -> wxyz
            chans.append((node_to_joint[node], prop, times, vals, interp))
            t_lo, t_hi = min(t_lo, times[0]), max(t_hi, times[-1])
        if not chans:
            continue
        # Uniform samples from the first key; a partial last step shorter than 1/fps is dropped.
        n = max(1, int(np.floor((t_hi - t_lo) * fps + 1e-3)) + 1)  # float32 key times: 1e-3 frame slack
        t = t_lo + np.arange(n) / fps
        tr = np.repeat(rest_t[None], n, 0)
        rq = np.repeat(rest_q[None], n, 0)
        sc = np.repeat(rest_s[None], n, 0)
        for j, prop, times, vals, interp in chans:
            s = _sample(times, vals, interp, t, prop == "rotation")
            {"translation": tr, "rotation": rq, "scale": sc}[prop][:, j] = s
        name = str(anim.get("name") or f"anim{ai}")
        base, k = name, 1
        while name in clips:
            k += 1
            name = f"{base}.{k}"
        clips[name] = Clip(
            name=name,
            fps=float(fps),
            rotations=rq.astype(np.float32),
            translations=tr.astype(np.float32),
            scales=sc.astype(np.float32),
        )
    return clips
