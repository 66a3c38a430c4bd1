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
  baseColorTexture is kept with TEXCOORD_0, and so is TEXCOORD_0 without any texture.
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
from ..files import NotRegularFileError, TooLargeError, read_input, read_regular
from ..geometry import compose_trs, decompose_trs, quat_normalize, quat_slerp
from ..limits import check as check_limit
from ..limits import check_read

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
READ_FACTOR = 4  # a file's readers may take its accessors' elements this many times --max-elements


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
            check_read(f"{path}: its glTF JSON is", len(data), "max_json_mb")
            try:
                self.json = json.loads(data.decode("utf-8"))
            except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
                raise InputError(f"{path}: not a glTF JSON file ({exc})") from None
        if not isinstance(self.json, dict) or not isinstance(self.json.get("asset"), dict):
            raise InputError(f"{path}: not a glTF 2.0 document (no 'asset' object)")
        version = str(self.json["asset"].get("version", ""))
        if not version.startswith("2"):
            raise InputError(
                f"{path}: glTF version {version!r} is not supported", hint="convert it to glTF 2.0"
            )
        self._buffers: dict[int, bytes] = {}
        self._checked: dict[str, list[dict[str, Any]]] = {}
        self._accessors: dict[int, np.ndarray] = {}
        self._handed_out = 0  # elements returned by accessor(), cached or not

    def get(self, key: str) -> list[dict[str, Any]]:
        if key in self._checked:  # checked once: readers call this for every accessor they read
            return self._checked[key]
        v = self.json.get(key, [])
        if not isinstance(v, list):
            raise InputError(f"{self.path}: '{key}' must be an array")
        for i, x in enumerate(v):
            if not isinstance(x, dict):
                raise InputError(f"{self.path}: {key}[{i}] must be an object")
        self._checked[key] = v
        return v

    def index(self, value: Any, key: str, what: str) -> int:
        """``value`` as an index into the top-level array ``key``, or a clear error."""
        n = len(self.get(key))
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value < n:
            raise InputError(f"{self.path}: {what} refers to {key}[{value!r}], which does not exist")
        return value

    def buffer(self, i: int) -> bytes:
        if i not in self._buffers:
            b = self.get("buffers")[self.index(i, "buffers", "a bufferView")]
            uri = b.get("uri")
            length = _count(self.path, b, "byteLength", f"buffer {i}")
            check_read(f"{self.path}: buffer {i} declares", length, "max_file_mb")
            if uri is None:
                if self.glb_bin is None:
                    raise InputError(f"{self.path}: buffer {i} has no uri and there is no GLB binary chunk")
                data = self.glb_bin
            else:
                data = self._uri(uri, f"buffer {i}")
            if len(data) < length:
                raise InputError(
                    f"{self.path}: buffer {i} is truncated ({len(data)} of {length} bytes)",
                    hint="the file was cut short; re-export or re-download it",
                )
            self._buffers[i] = data
        return self._buffers[i]

    def _uri(self, uri: Any, what: str) -> bytes:
        if not isinstance(uri, str):
            raise InputError(f"{self.path}: {what} has a uri that is not a string")
        if uri.startswith("data:"):
            return _data_uri(self.path, uri, what)
        return _read_beside(self.path, self.base, uri, what)

    def view_bytes(self, vi: Any) -> tuple[bytes, int, int, int | None]:
        """(buffer, offset, length, stride) of bufferView ``vi``, checked against its buffer."""
        vi = self.index(vi, "bufferViews", "an accessor or image")
        v = self.get("bufferViews")[vi]
        what = f"bufferView {vi}"
        buf = self.buffer(v.get("buffer"))
        off = _count(self.path, v, "byteOffset", what, default=0)
        length = _count(self.path, v, "byteLength", what)
        stride = v.get("byteStride")
        if stride is not None:
            stride = _count(self.path, v, "byteStride", what)
            if stride == 0:
                raise InputError(f"{self.path}: {what} has byteStride 0")
        if off + length > len(buf):
            raise InputError(f"{self.path}: {what} runs past the end of its buffer (truncated file?)")
        return buf, off, length, stride

    def accessor(self, ai: Any) -> np.ndarray:
        """Accessor ``ai`` as a read-only (count, components) array, decoded once.

        Every call counts against a budget of a few times `--max-elements`: a small file whose
        thousands of primitives, channels or skins name the same large accessor would otherwise
        make its readers copy it thousands of times."""
        ai = self.index(ai, "accessors", "a mesh, skin or animation")
        if ai not in self._accessors:
            out = self._decode(ai)
            out.flags.writeable = False
            self._accessors[ai] = out
        out = self._accessors[ai]
        self._handed_out += len(out)
        check_limit(
            f"{self.path}: its meshes, skins and animations read",
            self._handed_out,
            "max_elements",
            " accessor elements",
            factor=READ_FACTOR,
        )
        return out

    def _decode(self, ai: int) -> np.ndarray:
        a = self.get("accessors")[ai]
        what = f"accessor {ai}"
        ctype, atype = a.get("componentType"), a.get("type")
        if not isinstance(ctype, int) or ctype not in _COMPONENT:
            _bad(self.path, f"{what} component type {ctype!r}")
        if not isinstance(atype, str) or atype not in _NCOMP:
            _bad(self.path, f"{what} type {atype!r}")
        dtype, nc = np.dtype(_COMPONENT[ctype]), _NCOMP[atype]
        count = _count(self.path, a, "count", what)
        check_limit(f"{self.path}: {what} has", count, "max_elements", " elements")
        if "bufferView" in a:
            buf, off, vlen, stride = self.view_bytes(a["bufferView"])
            start = off + _count(self.path, a, "byteOffset", what, default=0)
            elem = dtype.itemsize * nc
            stride = stride or elem
            if stride < elem:
                raise InputError(
                    f"{self.path}: {what}'s bufferView stride {stride} is shorter than one element"
                )
            need = start + stride * (count - 1) + elem if count else start
            if need > off + vlen:
                raise InputError(f"{self.path}: {what} runs past the end of its bufferView (truncated file?)")
            if stride == elem:
                out = (
                    np.frombuffer(buf, dtype=dtype, count=count * nc, offset=start).reshape(count, nc).copy()
                )
            elif count:
                raw = np.frombuffer(buf, dtype=np.uint8, count=stride * (count - 1) + elem, offset=start)
                rows = np.lib.stride_tricks.as_strided(raw, shape=(count, elem), strides=(stride, 1))
                out = rows.copy().view(dtype).reshape(count, nc)
            else:
                out = np.zeros((0, nc), dtype=dtype)
        else:
            out = np.zeros((count, nc), dtype=dtype)
        sparse = a.get("sparse")
        if sparse is not None:
            out = self._sparse(ai, sparse, out, dtype, nc)
        if a.get("normalized") and dtype.kind in "iu":
            info = np.iinfo(dtype)
            out = np.maximum(out.astype(np.float64) / info.max, -1.0)
        return out

    def _sparse(self, ai: int, sparse: Any, out: np.ndarray, dtype: np.dtype, nc: int) -> np.ndarray:
        what = f"sparse accessor {ai}"
        if not isinstance(sparse, dict):
            raise InputError(f"{self.path}: {what} is not an object")
        n = _count(self.path, sparse, "count", what)
        if n > len(out):
            raise InputError(f"{self.path}: {what} has more sparse values ({n}) than elements ({len(out)})")
        idx_info, val_info = sparse.get("indices"), sparse.get("values")
        if not isinstance(idx_info, dict) or not isinstance(val_info, dict):
            raise InputError(f"{self.path}: {what} lacks its indices or values")
        idx_type = idx_info.get("componentType")
        if idx_type not in (5121, 5123, 5125):
            raise InputError(f"{self.path}: {what} has an invalid index component type")
        idx = self._view_array(idx_info, np.dtype(_COMPONENT[idx_type]), n, what)
        vals = self._view_array(val_info, dtype, n * nc, what).reshape(n, nc)
        if idx.size and idx.max() >= len(out):
            raise InputError(f"{self.path}: {what} has indices out of range")
        out = out.copy()
        out[idx.astype(np.int64)] = vals
        return out

    def _view_array(self, info: dict[str, Any], dtype: np.dtype, n: int, what: str) -> np.ndarray:
        buf, off, vlen, _ = self.view_bytes(info.get("bufferView"))
        start = off + _count(self.path, info, "byteOffset", what, default=0)
        if start + n * dtype.itemsize > off + vlen:
            raise InputError(f"{self.path}: {what} runs past the end of its bufferView (truncated file?)")
        return np.frombuffer(buf, dtype=dtype, count=n, offset=start)

    def image_bytes(self, ii: Any) -> bytes | None:
        images = self.get("images")
        if isinstance(ii, bool) or not isinstance(ii, int) or not 0 <= ii < len(images):
            return None
        im = images[ii]
        if "bufferView" in im:
            buf, off, length, _ = self.view_bytes(im["bufferView"])
            return bytes(buf[off : off + length])
        if "uri" in im:
            return self._uri(im["uri"], f"image {ii}")
        return None


def _count(path: Path, obj: dict[str, Any], key: str, what: str, default: int | None = None) -> int:
    """A non-negative integer field (counts, offsets, lengths), or a clear error."""
    v = obj.get(key, default)
    if v is None:
        raise InputError(f"{path}: {what} has no {key}")
    if isinstance(v, bool) or not isinstance(v, int) or v < 0:
        raise InputError(f"{path}: {what} has {key} {v!r}; it must be a non-negative integer")
    return v


def _data_uri(path: Path, uri: str, what: str) -> bytes:
    from urllib.parse import unquote_to_bytes

    head, sep, body = uri.partition(",")
    if not sep:
        raise InputError(f"{path}: {what} has a malformed data URI")
    if head.endswith(";base64"):
        try:
            return base64.b64decode(body, validate=True)
        except ValueError:
            raise InputError(f"{path}: {what} has a malformed base64 data URI") from None
    return unquote_to_bytes(body)


def _read_beside(path: Path, base: Path, uri: str, what: str) -> bytes:
    """The file a relative URI names, which must lie inside the glTF file's folder (after
    following symlinks): an absolute path, a ``..`` escape or a link out of the folder would let
    a downloaded model read any file the user can."""
    from urllib.parse import unquote, urlsplit

    rel = unquote(uri)
    scheme = urlsplit(uri).scheme
    hint = f"keep the files it uses in {path.name}'s folder (or below), or export a self-contained .glb"
    if (scheme and len(scheme) > 1) or Path(rel).is_absolute() or rel.startswith(("/", "\\")) or "\0" in rel:
        raise InputError(
            f"{path}: {what} refers to {uri!r}; only relative file names and data URIs are allowed", hint=hint
        )
    try:
        folder, target = base.resolve(), (base / rel).resolve()
    except (OSError, RuntimeError) as exc:  # a symlink loop
        raise InputError(
            f"{path}: {what} refers to {uri!r}, which cannot be resolved ({exc})", hint=hint
        ) from None
    if not target.is_relative_to(folder) or len(scheme) == 1:
        raise InputError(
            f"{path}: {what} refers to {uri!r}, which is outside the glTF file's folder", hint=hint
        )
    if not target.exists():
        raise InputError(
            f"{path}: {what} refers to {uri!r}, which is missing",
            hint=f"put {uri} next to {path.name}, or export a self-contained .glb",
        )
    try:
        return read_regular(target, "max_file_mb")
    except (NotRegularFileError, TooLargeError) as exc:
        hint = exc.hint if isinstance(exc, TooLargeError) else hint
        raise InputError(f"{path}: {what} refers to {uri!r}, which is {exc.strerror}", hint=hint) from None
    except OSError as exc:
        raise InputError(f"{path}: {what} refers to {uri!r}, which is unreadable ({exc.strerror})") from None


def _bad(path: Path, what: str) -> Any:
    raise InputError(f"{path}: invalid {what}")


def _read_bytes(path: Path) -> bytes:
    if path.is_dir():
        raise InputError(f"{path} is a directory", hint="give a .glb or .gltf file")
    if not path.exists():
        raise InputError(f"{path} does not exist")
    data = read_input(path, "the model file")
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
            check_read(f"{path}: its GLB JSON chunk is", clen, "max_json_mb")
            try:
                js = json.loads(chunk.decode("utf-8"))
            except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
                raise InputError(f"{path}: GLB JSON chunk is malformed ({exc})") from None
        elif ctype == 0x004E4942 and binary is None:
            binary = chunk
        off += 8 + clen
    if js is None:
        raise InputError(f"{path}: GLB has no JSON chunk")
    return js, binary


def _node_local(path: Path, i: int, node: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rest TRS of a node (from its matrix when it has one)."""
    if "matrix" in node:
        m = _floats(path, node["matrix"], 16, f"node {i} matrix").reshape(4, 4).T  # column-major
        if not np.any(m[:3, :3]):  # scale 0, as a TRS node may have
            return m[:3, 3].copy(), np.array([1.0, 0, 0, 0]), np.zeros(3)
        t, q, s = decompose_trs(m)
        back = compose_trs(t[None], q[None], s[None])[0]
        if not np.allclose(back[:3, :3], m[:3, :3], atol=1e-4 * np.abs(m[:3, :3]).max()):
            raise InputError(
                f"{path}: node {i} matrix is singular or sheared; glTF node matrices must be "
                "translation x rotation x scale"
            )
        return t, q, s
    t = _floats(path, node.get("translation", [0, 0, 0]), 3, f"node {i} translation")
    x, y, z, w = _floats(path, node.get("rotation", [0, 0, 0, 1]), 4, f"node {i} rotation")
    if not (x or y or z or w):
        raise InputError(f"{path}: node {i} has a zero rotation quaternion")
    q = quat_normalize(np.array([w, x, y, z], dtype=np.float64))
    s = _floats(path, node.get("scale", [1, 1, 1]), 3, f"node {i} scale")
    return t, q, s


def _floats(path: Path, value: Any, n: int, what: str) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        a = None
    if a is None or a.shape != (n,):
        raise InputError(f"{path}: {what} must be {n} numbers")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{path}: {what} contains NaN or infinity")
    return a


def _triangles(doc: _Doc, prim: dict[str, Any], nverts: int) -> np.ndarray:
    mode = prim.get("mode", 4)
    if "indices" in prim:
        idx = doc.accessor(prim["indices"]).reshape(-1).astype(np.int64)
    else:
        idx = np.arange(nverts, dtype=np.int64)
    if mode == 4:
        tris = idx[: len(idx) // 3 * 3].reshape(-1, 3)
    elif mode == 5:  # strip: every other triangle has its winding flipped
        k = np.arange(max(len(idx) - 2, 0))
        odd = k % 2 == 1
        tris = np.stack([np.where(odd, idx[k + 1], idx[k]), np.where(odd, idx[k], idx[k + 1]), idx[k + 2]], 1)
    elif mode == 6:  # fan
        k = np.arange(1, max(len(idx) - 1, 1))
        tris = np.stack([np.full(len(k), idx[0] if len(idx) else 0), idx[k], idx[k + 1]], 1)
    else:
        return np.zeros((0, 3), dtype=np.int64)
    tris = tris.reshape(-1, 3)
    if tris.size and (tris.min() < 0 or tris.max() >= nverts):
        raise InputError(f"{doc.path}: triangle indices out of range of the {nverts} vertices")
    return tris


def _hierarchy(path: Path, nodes: list[dict[str, Any]]) -> np.ndarray:
    """Parent index of every node (-1 for roots); a node with two parents or a cycle is an error."""
    parent = np.full(len(nodes), -1, dtype=np.int64)
    for i, n in enumerate(nodes):
        children = n.get("children", [])
        if not isinstance(children, list):
            raise InputError(f"{path}: node {i} children must be an array")
        for c in children:
            if isinstance(c, bool) or not isinstance(c, int) or not (0 <= c < len(nodes)) or parent[c] != -1:
                raise InputError(f"{path}: node hierarchy is not a tree (node {c!r})")
            parent[c] = i
    # Every node must reach a root; a node on a cycle never does.
    done = np.zeros(len(nodes), dtype=bool)
    for i in range(len(nodes)):
        chain = []
        j = i
        while j >= 0 and not done[j]:
            if len(chain) > len(nodes):
                raise InputError(f"{path}: node hierarchy has a cycle (through node {i})")
            chain.append(j)
            j = int(parent[j])
        done[chain] = True
    return parent


def _joint_anchors(
    parent: np.ndarray, node_to_joint: dict[int, int], rest_m: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Each node's nearest skeleton ancestor (-1: none) and its transform relative to it, found
    in one pass (no walk per node) and without inverting the joint (it may have scale 0)."""
    n = len(parent)
    anchor = np.full(n, -2, dtype=np.int64)
    below = np.empty_like(rest_m)
    for i in range(n):
        chain = []
        j = i
        while j >= 0 and anchor[j] == -2:
            chain.append(j)
            j = int(parent[j])
        for k in reversed(chain):
            p = int(parent[k])
            if p < 0 or p in node_to_joint:
                anchor[k], below[k] = p, rest_m[k]
            else:
                anchor[k], below[k] = anchor[p], below[p] @ rest_m[k]
    return anchor, below


def _check_invertible(path: Path, m: np.ndarray, names: list[str], what: str) -> None:
    """A rest-pose or bind matrix that cannot be inverted (a zero scale) is an input error."""
    if not len(m):
        return
    finite = np.all(np.isfinite(m), axis=(1, 2))
    # LAPACK prints to stdout on a NaN ("On entry to DLASCL..."): only finite matrices go to the SVD
    sv = np.linalg.svd(np.where(finite[:, None, None], m[:, :3, :3], np.eye(3)), compute_uv=False)
    bad = ~finite | (sv[:, -1] <= 1e-9 * np.maximum(sv[:, 0], 1e-30))
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise InputError(
            f"{path}: {what} of {names[k]!r} is singular (a zero scale?)",
            hint="give it a non-zero scale in the source file; zooctl needs an invertible rest pose",
        )


def load_gltf(path: str | Path, name: str, fps: float = 30.0) -> RiggedAsset:
    """Import a glTF 2.0 file as a validated `RiggedAsset` (see the module docstring)."""
    path = Path(path)
    try:
        return _load(path, name, fps).validate()  # after _load's temporaries are gone
    except InputError as exc:
        if exc.hint is None:
            exc.hint = "the file is damaged or not glTF 2.0: re-export it, or check it with the Khronos glTF validator"
        raise
    except (KeyError, TypeError, ValueError, IndexError, AttributeError, OverflowError) as exc:
        # The checks above name what they know; any other structural defect of the JSON (a
        # string where an object belongs, a missing key) still gets one line, not a traceback.
        what = f"{type(exc).__name__}: {str(exc).splitlines()[0][:200] if str(exc) else ''}"
        raise InputError(
            f"{path}: malformed glTF ({what})",
            hint="check it with the Khronos glTF validator; ZOOCTL_DEBUG=1 shows where it failed",
        ) from exc


def _load(path: Path, name: str, fps: float) -> RiggedAsset:
    doc = _Doc(path)
    nodes = doc.get("nodes")
    skins = doc.get("skins")
    if not skins:
        raise InputError(
            f"{path}: the file has no skin (no rigged mesh)", hint="zooctl needs a skinned, rigged mesh"
        )
    parent = _hierarchy(path, nodes)
    rest = [_node_local(path, i, n) for i, n in enumerate(nodes)]
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
    used_skins = sorted({doc.index(n["skin"], "skins", f"node {i}") for i, n in skinned})

    # Skeleton = skin joints of the used skins plus all their ancestors, in depth-first order.
    joint_nodes: set[int] = set()
    for s in used_skins:
        sk_joints = skins[s].get("joints")
        if not isinstance(sk_joints, list) or not sk_joints:
            raise InputError(f"{path}: skin {s} has no joints")
        for j in sk_joints:
            joint_nodes.add(doc.index(j, "nodes", f"skin {s}"))
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
    names = _unique_names([str(nodes[n].get("name") or f"node{n}") for n in order])
    rest_local = rest_m[order]
    ibm = np.tile(np.eye(4), (J, 1, 1))
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
        _check_invertible(
            path,
            m,
            [str(nodes[j].get("name") or f"node{j}") for j in sk["joints"]],
            "the inverse bind matrix",
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
    # Ancestors that are not skin joints are bound where they rest.
    free = np.flatnonzero(~assigned)
    _check_invertible(path, world[np.array(order)[free]], [names[k] for k in free], "the rest transform")
    ibm[free] = np.linalg.inv(world[np.array(order)[free]])

    parts = _MeshParts(path, doc)
    warnings: list[str] = []
    per_skin: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    for node_i, node in skinned:
        s = doc.index(node["skin"], "skins", f"node {node_i}")
        if s not in per_skin:
            skin_joints = np.array([node_to_joint[int(j)] for j in skins[s]["joints"]], dtype=np.int64)
            # A skin whose bind matrices differ from the canonical ones by one transform M gets v -> M v.
            fix = np.linalg.inv(ibm[skin_joints]) @ ibm_skin[s]
            if not np.allclose(fix, fix[:1], atol=1e-4 * max(1.0, float(np.abs(fix).max()))):
                raise InputError(f"{path}: skins {first} and {s} bind the same joints inconsistently")
            per_skin[s] = skin_joints, fix[0]
        skin_joints, M = per_skin[s]
        for prim, (v, f, col, uv, tex) in parts.primitives(node["mesh"]):
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
            parts.add(v, f, jj, ww, col, uv, tex)

    # Rigid attachments: unskinned meshes under a joint follow that joint with weight 1.
    anchor, below = _joint_anchors(parent, node_to_joint, rest_m)
    for i, node in enumerate(nodes):
        if "mesh" not in node or "skin" in node or anchor[i] < 0:
            continue
        jj_i = node_to_joint[int(anchor[i])]
        to_bind = np.linalg.inv(ibm[jj_i]) @ below[i]
        for _, (v, f, col, uv, tex) in parts.primitives(node["mesh"]):
            v = v @ to_bind[:3, :3].T + to_bind[:3, 3]
            n = v.shape[0]
            parts.add(v, f, np.full((n, 1), jj_i, dtype=np.int64), np.ones((n, 1)), col, uv, tex)

    if not parts.verts:
        raise InputError(f"{path}: the skinned meshes have no triangles")
    K = max(x.shape[1] for x in parts.joints)
    sj = [np.pad(x, ((0, 0), (0, K - x.shape[1]))) for x in parts.joints]
    sw = [np.pad(x, ((0, 0), (0, K - x.shape[1]))) for x in parts.weights]
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

    vertex_colors = np.concatenate(parts.colors).astype(np.float32)
    uv_all = None
    texture = None
    distinct_tex = {t for t in parts.textures if t is not None}
    if len(distinct_tex) == 1 and all(u is not None for u in parts.uvs):
        uv_all = np.concatenate(parts.uvs).astype(np.float32)
        texture = _texture_png(doc, distinct_tex.pop(), warnings)
        if texture is None:
            uv_all = None
    elif not distinct_tex and all(u is not None for u in parts.uvs):
        uv_all = np.concatenate(parts.uvs).astype(np.float32)  # no texture: a fit can bake one

    clips = _clips(doc, nodes, node_to_joint, rest, order, fps)
    asset = RiggedAsset(
        name=name,
        vertices=np.concatenate(parts.verts).astype(np.float32),
        faces=np.concatenate(parts.faces).astype(np.int32),
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
            **_label_extras(doc.json),
        },
    )
    return asset


def _label_extras(doc: dict) -> dict[str, str]:
    """The animal label a zooctl export wrote into the asset's extras, so a round trip keeps it."""
    extras = doc.get("asset", {}).get("extras")
    label = extras.get("label") if isinstance(extras, dict) else None
    return (
        {"label": label.strip(), "label_source": "given"} if isinstance(label, str) and label.strip() else {}
    )


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


class _MeshParts:
    """The triangle primitives of a skinned asset as they are gathered, vertex indices offset into
    one mesh: vertices (n, 3), faces (m, 3), skin joints and weights (n, k), colours, uvs, texture."""

    def __init__(self, path: Path, doc: _Doc) -> None:
        self.path, self.doc = path, doc
        self.meshes, self.materials = doc.get("meshes"), doc.get("materials")
        self.verts: list[np.ndarray] = []
        self.faces: list[np.ndarray] = []
        self.joints: list[np.ndarray] = []
        self.weights: list[np.ndarray] = []
        self.colors: list[np.ndarray] = []
        self.uvs: list[np.ndarray | None] = []
        self.textures: list[Any] = []
        self.offset = 0

    def primitives(self, mesh_index: Any):
        """(primitive, (v, f, col, uv, tex)) for each triangle primitive of mesh ``mesh_index``,
        checked against the vertex limit before it is used."""
        for prim in _mesh(self.doc, self.meshes, mesh_index):
            got = _primitive(self.doc, prim, self.materials)
            if got is None:
                continue
            check_limit(
                f"{self.path}: the meshes have", self.offset + len(got[0]), "max_vertices", " vertices"
            )
            yield prim, got

    def add(self, v, f, joints, weights, col, uv, tex) -> None:
        self.verts.append(v)
        self.faces.append(f + self.offset)
        self.joints.append(joints)
        self.weights.append(weights)
        self.colors.append(col)
        self.uvs.append(uv)
        self.textures.append(tex)
        self.offset += v.shape[0]


def _mesh(doc: _Doc, meshes: list[dict[str, Any]], mi: Any) -> list[dict[str, Any]]:
    """The primitives of mesh ``mi``."""
    prims = meshes[doc.index(mi, "meshes", "a node")].get("primitives")
    if not isinstance(prims, list) or not all(isinstance(x, dict) for x in prims):
        raise InputError(f"{doc.path}: mesh {mi} primitives must be an array of objects")
    return prims


def _primitive(doc: _Doc, prim: dict[str, Any], materials: list[dict[str, Any]]):
    attrs = prim.get("attributes", {})
    if not isinstance(attrs, dict):
        raise InputError(f"{doc.path}: primitive attributes must be an object")
    if "POSITION" not in attrs or prim.get("mode", 4) not in (4, 5, 6):
        return None
    v = doc.accessor(attrs["POSITION"]).astype(np.float64)
    if v.shape[1] != 3:
        raise InputError(f"{doc.path}: POSITION must be VEC3")
    if not np.all(np.isfinite(v)):
        raise InputError(f"{doc.path}: vertex positions contain NaN or infinity")
    f = _triangles(doc, prim, v.shape[0])
    mat = materials[doc.index(prim["material"], "materials", "a primitive")] if "material" in prim else {}
    pbr = mat.get("pbrMetallicRoughness", {})
    pbr = pbr if isinstance(pbr, dict) else {}
    base = _floats(doc.path, pbr.get("baseColorFactor", [1, 1, 1, 1]), 4, "baseColorFactor")[:3]
    col = np.tile(base, (v.shape[0], 1))
    if "COLOR_0" in attrs:
        c = doc.accessor(attrs["COLOR_0"]).astype(np.float64)
        if c.shape[0] != v.shape[0] or c.shape[1] < 3:
            raise InputError(f"{doc.path}: COLOR_0 does not match the vertices")
        col = col * np.nan_to_num(c[:, :3])
    uv = None
    if "TEXCOORD_0" in attrs:
        uv = doc.accessor(attrs["TEXCOORD_0"]).astype(np.float64)
        if uv.shape != (v.shape[0], 2) or not np.all(np.isfinite(uv)):
            uv = None  # unusable UVs: the mesh keeps its colours, without the texture
    tex = pbr.get("baseColorTexture", {})
    tex = tex.get("index") if isinstance(tex, dict) else None
    tex = tex if isinstance(tex, int) and not isinstance(tex, bool) else None
    return v, f, np.clip(col, 0, 1), uv, tex


MAX_TEXTURE_PIXELS = 8192 * 8192


def _texture_png(doc: _Doc, tex_index: Any, warnings: list[str]) -> bytes | None:
    textures = doc.get("textures")
    if isinstance(tex_index, bool) or not isinstance(tex_index, int) or not 0 <= tex_index < len(textures):
        return None
    data = doc.image_bytes(textures[tex_index].get("source"))
    if data is None:
        return None
    if data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR":
        w, h = struct.unpack(">II", data[16:24])
        if w * h > MAX_TEXTURE_PIXELS:
            warnings.append(f"texture of {w}x{h} pixels dropped (more than {MAX_TEXTURE_PIXELS:,} pixels)")
            return None
        return data
    try:
        from PIL import Image

        im = Image.open(io.BytesIO(data))
        if im.width * im.height > MAX_TEXTURE_PIXELS:
            warnings.append(
                f"texture of {im.width}x{im.height} pixels dropped (more than {MAX_TEXTURE_PIXELS:,} pixels)"
            )
            return None
        buf = io.BytesIO()
        im.convert("RGBA").save(buf, format="PNG")
        return buf.getvalue()
    except Exception:  # an undecodable image: the asset keeps its vertex colours
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


@np.errstate(over="ignore", invalid="ignore")  # a huge scale overflows: `_check_invertible` says so
def _world(local: np.ndarray, parent: np.ndarray) -> np.ndarray:
    """World transforms of a forest given by ``parent`` (acyclic, see `_hierarchy`), without
    recursion: a chain of thousands of nodes must not overflow the stack."""
    out = np.empty_like(local)
    done = np.zeros(len(local), dtype=bool)
    for i in range(len(local)):
        chain = []
        j = i
        while j >= 0 and not done[j]:
            chain.append(j)
            j = int(parent[j])
        for k in reversed(chain):
            p = parent[k]
            out[k] = out[p] @ local[k] if p >= 0 else local[k]
            done[k] = True
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


_WIDTH = {"translation": 3, "rotation": 4, "scale": 3}


def _channel(doc: _Doc, ai: int, samplers: list[Any], ch: dict[str, Any], prop: str):
    """(times, values, interpolation) of one channel, checked against the glTF rules."""
    si = ch.get("sampler")
    if isinstance(si, bool) or not isinstance(si, int) or not 0 <= si < len(samplers):
        raise InputError(f"{doc.path}: animation {ai} refers to a missing sampler")
    smp = samplers[si]
    if not isinstance(smp, dict) or "input" not in smp or "output" not in smp:
        raise InputError(f"{doc.path}: animation {ai} sampler {si} lacks its input or output")
    interp = smp.get("interpolation", "LINEAR")
    if interp not in ("LINEAR", "STEP", "CUBICSPLINE"):
        raise InputError(f"{doc.path}: animation {ai} uses unknown interpolation {interp!r}")
    times = doc.accessor(smp["input"]).reshape(-1).astype(np.float64)
    vals = doc.accessor(smp["output"]).astype(np.float64)
    per_key = 3 if interp == "CUBICSPLINE" else 1  # in-tangent, value, out-tangent
    if vals.shape != (per_key * len(times), _WIDTH[prop]):
        raise InputError(
            f"{doc.path}: animation {ai} sampler {si} has {vals.shape[0]} {prop} values of "
            f"{vals.shape[1]} components for {len(times)} {interp} keyframes "
            f"(expected {per_key * len(times)} of {_WIDTH[prop]})"
        )
    if not (np.all(np.isfinite(times)) and np.all(np.isfinite(vals))):
        raise InputError(f"{doc.path}: animation {ai} contains NaN or infinity")
    if np.any(np.diff(times) < 0):
        raise InputError(f"{doc.path}: animation {ai} sampler {si} has keyframe times that go backwards")
    return times, vals, interp


@np.errstate(over="ignore", invalid="ignore")  # values past float32 become inf: the clip check names them
def _clips(doc: _Doc, nodes, node_to_joint, rest, order, fps: float) -> dict[str, Clip]:
    clips: dict[str, Clip] = {}
    rest_t = np.array([rest[n][0] for n in order])
    rest_q = np.array([rest[n][1] for n in order])
    rest_s = np.array([rest[n][2] for n in order])
    total_frames = 0
    for ai, anim in enumerate(doc.get("animations")):
        samplers = anim.get("samplers", [])
        channels = anim.get("channels", [])
        if not isinstance(samplers, list) or not isinstance(channels, list):
            raise InputError(f"{doc.path}: animation {ai} samplers and channels must be arrays")
        targeted: dict[tuple[int, str], dict[str, Any]] = {}
        for ch in channels:
            tgt = ch.get("target", {}) if isinstance(ch, dict) else None
            if not isinstance(tgt, dict):
                raise InputError(f"{doc.path}: animation {ai} has a channel without a target")
            node, prop = tgt.get("node"), tgt.get("path")
            if isinstance(node, int) and isinstance(prop, str):
                targeted[node, prop] = ch  # one channel per joint and property: the last one
        chans = []
        t_lo, t_hi = np.inf, -np.inf
        for (node, prop), ch in targeted.items():
            if node not in node_to_joint or prop not in _WIDTH:
                continue
            times, vals, interp = _channel(doc, ai, samplers, ch, prop)
            if times.size == 0:
                continue
            if prop == "rotation":
                vals = vals[:, [3, 0, 1, 2]]  # xyzw -> wxyz
            chans.append((node_to_joint[node], prop, times, vals, interp))
            t_lo, t_hi = min(t_lo, times[0]), max(t_hi, times[-1])
        if not chans:
            continue
        name = str(anim.get("name") or f"anim{ai}")
        check_limit(f"{doc.path}: animation {name!r} lasts", t_hi - t_lo, "max_clip_seconds", " s")
        # Uniform samples from the first key; a partial last step shorter than 1/fps is dropped.
        n = max(1, int(np.floor((t_hi - t_lo) * fps + 1e-3)) + 1)  # float32 key times: 1e-3 frame slack
        total_frames += n
        check_limit(f"{doc.path}: the animations have", total_frames, "max_frames", " frames")
        joint_frames = total_frames * len(order)
        check_limit(f"{doc.path}: the animations have", joint_frames, "max_elements", " joint-frames")
        t = t_lo + np.arange(n) / fps
        # float32 from the start: a long clip is not held twice
        tr = np.repeat(rest_t[None].astype(np.float32), n, 0)
        rq = np.repeat(rest_q[None].astype(np.float32), n, 0)
        sc = np.repeat(rest_s[None].astype(np.float32), n, 0)
        for j, prop, times, vals, interp in chans:
            s = _sample(times, vals, interp, t, prop == "rotation")
            {"translation": tr, "rotation": rq, "scale": sc}[prop][:, j] = s
        base, k = name, 1
        while name in clips:
            k += 1
            name = f"{base}.{k}"
        clips[name] = Clip(name=name, fps=float(fps), rotations=rq, translations=tr, scales=sc)
    return clips
