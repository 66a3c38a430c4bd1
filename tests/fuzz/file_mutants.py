"""Mutated glTF, GLB and USD files for the import fuzz, and the runner that imports them.

`mutants(workdir, n, seed)` writes ``n`` damaged files made from real ones (the shared Quaternius
animals when present, the hand-built two-bone rig always) with one random edit each: JSON fields
(negative or huge counts and offsets, wrong types, missing keys, bad indices, NaN, cyclic parents,
escaping URIs), the binary chunk (huge or NaN key times, bit flips, truncation) or the USD text
(duplicate or reordered joints, bad sublayers, missing attributes, huge time samples); or the
file itself: a FIFO, socket or device (its own or its buffer's), a sparse 16 GB file, a buffer
declaring a terabyte.

`run(cases, store, ...)` imports each one with `bank add` into a scratch store, in a worker process
(fast: the library in-process) and, for some, the real CLI in a subprocess, and classifies the
outcome. A case passes when it ends in success or a clear one-line error within `TIMEOUT_S`, under
`MAX_RSS_KB`, leaving every other stored file byte-identical.

Used by tests/fuzz/test_file_fuzz.py (a quick subset) and bench/fuzz_files.py (the full run).
"""

from __future__ import annotations

import copy
import hashlib
import json
import os
import re
import select
import struct
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
TESTS = HERE.parent
REPO = TESTS.parent
SHARED_ASSETS = REPO.parent / "shared" / "data" / "assets" / "quaternius"
sys.path[:0] = [str(TESTS)] if str(TESTS) not in sys.path else []

from gltf_builder import glb_bytes, tiny_gltf, with_texture  # noqa: E402

TIMEOUT_S = 60
MAX_RSS_KB = 2 * 1024 * 1024
SMALL_SHARED = ["fish_pack/Dolphin.glb", "fish_pack/Whale.glb", "cute_fish_pack/Koi.glb"]
SECRET = b"SECRET-OUTSIDE-THE-MODEL-FOLDER"


@dataclass
class Case:
    name: str
    kind: str  # the mutation that made it
    path: Path
    must_fail: bool = False  # e.g. a URI escaping the folder: importing it would be a breach


@dataclass
class Outcome:
    case: Case
    via: str  # "library" or "cli"
    status: str  # ok | error | internal | hang | crash | memory | store_changed | breach | unclear
    detail: str = ""
    seconds: float = 0.0
    peak_kb: int = 0
    extra: dict = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        return self.status in ("ok", "error")


# -- seeds ------------------------------------------------------------------------------------


def _read_glb(data: bytes) -> tuple[dict, bytes]:
    off, js, binary = 12, None, b""
    while off + 8 <= len(data):
        n, kind = struct.unpack_from("<II", data, off)
        chunk = data[off + 8 : off + 8 + n]
        if kind == 0x4E4F534A:
            js = json.loads(chunk)
        elif kind == 0x004E4942:
            binary = chunk
        off += 8 + n
    return js, binary


def _seed_docs() -> list[tuple[str, dict, bytes]]:
    out = [("tiny", *tiny_gltf())]
    for rel in SMALL_SHARED:
        p = SHARED_ASSETS / rel
        if p.is_file():
            out.append((p.stem, *_read_glb(p.read_bytes())))
    return out


def _usd_seeds(workdir: Path) -> list[tuple[str, str]]:
    """(name, usda text) exported from the seed glTFs; none when pxr is missing."""
    try:
        import pxr  # noqa: F401
    except ImportError:
        return []
    from zooctl.io.gltf_import import load_gltf
    from zooctl.io.usd_export import save_usd

    out = []
    seeds = workdir / "_seeds"
    seeds.mkdir(parents=True, exist_ok=True)
    for name, doc, binary in _seed_docs()[:2]:
        glb = seeds / f"{name}.glb"
        glb.write_bytes(glb_bytes(doc, binary))
        usda = seeds / f"{name}.usda"
        save_usd(load_gltf(glb, name), usda)
        out.append((name, usda.read_text()))
    return out


# -- glTF mutations ---------------------------------------------------------------------------

_BAD_INTS = [-1, -16, -(2**31), 2**31, 10**12, "4", 4.5, None, True, [], {}]
_REFS = [
    ("nodes", "mesh", "meshes"),
    ("nodes", "skin", "skins"),
    ("nodes", "children", "nodes"),
    ("skins", "joints", "nodes"),
    ("skins", "inverseBindMatrices", "accessors"),
    ("accessors", "bufferView", "bufferViews"),
    ("bufferViews", "buffer", "buffers"),
]


def _bad_first_value(text: str, rng, prefix: str, value: str, choices: list[str]) -> str:
    """``text`` with the first value (regex ``value``) after the literal ``prefix`` replaced by one
    of ``choices`` (picked only when there is one to replace)."""
    return re.sub(re.escape(prefix) + value, lambda m: prefix + _pick(rng, choices), text, count=1)


def _pick(rng, items):
    return items[int(rng.integers(len(items)))]


def _objects(doc: dict, key: str) -> list[dict]:
    v = doc.get(key)
    return [x for x in v if isinstance(x, dict)] if isinstance(v, list) else []


def _json_mutation(rng, doc: dict, binary: bytearray) -> str:
    """Apply one random edit to ``doc`` (and maybe ``binary``) in place; return its kind."""
    kind = _pick(
        rng,
        [
            "count",
            "view_field",
            "accessor_field",
            "missing_key",
            "bad_index",
            "nan",
            "zero_scale",
            "cycle",
            "interpolation",
            "sampler_io",
            "wrong_type",
            "sparse",
            "mode",
            "skin_joints",
            "key_times",
            "bin_values",
            "asset",
            "amplify",
        ],
    )
    accs, views, nodes = _objects(doc, "accessors"), _objects(doc, "bufferViews"), _objects(doc, "nodes")
    if kind == "count":
        _pick(rng, accs)["count"] = _pick(rng, _BAD_INTS + [0])
    elif kind == "view_field":
        _pick(rng, views)[_pick(rng, ["byteOffset", "byteLength", "byteStride", "buffer"])] = _pick(
            rng, _BAD_INTS + [0, 1, 3, 255]
        )
    elif kind == "accessor_field":
        a = _pick(rng, accs)
        field_ = _pick(rng, ["byteOffset", "componentType", "type", "normalized", "bufferView"])
        a[field_] = _pick(rng, _BAD_INTS + [5121, 5124, "VEC5", "MAT4", "SCALAR", 1, 3])
    elif kind == "missing_key":
        coll = _pick(rng, ["accessors", "bufferViews", "nodes", "skins", "animations", "meshes", "buffers"])
        objs = _objects(doc, coll)
        if coll == "animations" and objs:
            a = _pick(rng, objs)
            objs = [x for x in a.get("samplers", []) + a.get("channels", []) if isinstance(x, dict)] or objs
        if coll == "meshes" and objs:
            objs = [p for m in objs for p in m.get("primitives", [])] or objs
        if objs:
            o = _pick(rng, objs)
            if o:
                del o[_pick(rng, sorted(o))]
    elif kind == "bad_index":
        coll, key, target = _pick(rng, _REFS)
        objs = [o for o in _objects(doc, coll) if key in o]
        if objs:
            o = _pick(rng, objs)
            bad = _pick(rng, [-1, len(doc.get(target, [])), 10**9, "0", 1.5, None])
            o[key] = [bad] if isinstance(o[key], list) else bad
    elif kind == "nan":
        n = _pick(rng, nodes)
        key = _pick(rng, ["translation", "rotation", "scale", "matrix"])
        width = {"translation": 3, "rotation": 4, "scale": 3, "matrix": 16}[key]
        vals = [0.0] * width
        vals[int(rng.integers(width))] = _pick(rng, [float("nan"), float("inf"), 1e308, -1e308])
        n[key] = vals
    elif kind == "zero_scale":
        n = _pick(rng, nodes)
        n.pop("matrix", None)
        if rng.random() < 0.5:
            n["scale"] = [0.0, 0.0, 0.0]
        else:
            n["matrix"] = _pick(
                rng, [[0.0] * 16, [1, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 1], [1, 2] * 8]
            )
    elif kind == "cycle":
        parents = {c: i for i, n in enumerate(nodes) for c in n.get("children", []) if isinstance(c, int)}
        child = _pick(rng, sorted(parents)) if parents else 0
        anc = child
        while anc in parents and rng.random() < 0.7:
            anc = parents[anc]
        nodes[child].setdefault("children", []).append(anc)
    elif kind == "interpolation":
        for a in _objects(doc, "animations")[:3]:
            for s in a.get("samplers", []):
                s["interpolation"] = _pick(rng, ["CUBICSPLINE", "STEP", "SMOOTH", 3, None])
    elif kind == "sampler_io":
        anims = _objects(doc, "animations")
        if anims:
            s = _pick(rng, _pick(rng, anims).get("samplers", [{}]))
            k = _pick(rng, ["input", "output"])
            s[k] = _pick(rng, [int(rng.integers(len(accs))), -1, len(accs), "x"])
    elif kind == "wrong_type":
        key = _pick(
            rng, ["nodes", "accessors", "bufferViews", "skins", "meshes", "animations", "buffers", "scenes"]
        )
        if rng.random() < 0.5:
            doc[key] = _pick(rng, [5, "x", {"0": {}}, None, [1, 2]])
        elif isinstance(doc.get(key), list) and doc[key]:
            doc[key][int(rng.integers(len(doc[key])))] = _pick(rng, [5, "x", [], None])
    elif kind == "sparse":
        a = _pick(rng, accs)
        a["sparse"] = {
            "count": _pick(rng, [1, 2, -1, 10**9, a.get("count", 1) + 1]),
            "indices": {
                "bufferView": _pick(rng, [0, 1, 99, -1]),
                "componentType": _pick(rng, [5123, 5125, 5126]),
            },
            "values": {"bufferView": _pick(rng, [0, 1, 99]), "byteOffset": _pick(rng, [0, -4, 2**40])},
        }
    elif kind == "mode":
        for m in _objects(doc, "meshes"):
            for p in m.get("primitives", []):
                p["mode"] = _pick(rng, [0, 1, 2, 3, 5, 6, 7, -1, "4"])
    elif kind == "skin_joints":
        s = _pick(rng, _objects(doc, "skins"))
        j = s.get("joints", [])
        s["joints"] = _pick(rng, [[], j + j[:1], j[::-1], j[:1], [10**6]])
    elif kind == "key_times":
        _edit_key_times(rng, doc, binary)
    elif kind == "bin_values":
        a = _pick(rng, [x for x in accs if x.get("componentType") == 5126 and "bufferView" in x] or accs)
        v = (
            views[a["bufferView"]]
            if isinstance(a.get("bufferView"), int) and a["bufferView"] < len(views)
            else None
        )
        if v is not None:
            start = v.get("byteOffset", 0) + a.get("byteOffset", 0)
            for _ in range(int(rng.integers(1, 4))):
                off = start + 4 * int(rng.integers(max(1, v["byteLength"] // 4)))
                binary[off : off + 4] = np.float32(_pick(rng, [np.nan, np.inf, 1e30, -1e30, 0.0])).tobytes()
    elif kind == "asset":
        doc["asset"] = _pick(rng, [{}, {"version": "1.0"}, "2.0", None, {"version": 2}])
    elif kind == "amplify":
        _amplify(rng, doc)
    return kind


def _amplify(rng, doc: dict) -> None:
    """Many references to the same data: a small file asking for a lot of work or memory."""
    k = int(_pick(rng, [1000, 5000, 20000]))
    op = _pick(rng, ["primitives", "channels", "skinned_nodes", "attached_nodes", "deep_chain"])
    nodes = doc["nodes"]
    if op == "primitives":
        doc["meshes"][0]["primitives"] = doc["meshes"][0]["primitives"] * (k // 10)
    elif op == "channels":
        for a in doc.get("animations", [])[:1]:
            a["channels"] = a["channels"] * (k // max(1, len(a["channels"])))
    elif op in ("skinned_nodes", "attached_nodes"):
        skinned = next(n for n in nodes if "skin" in n and "mesh" in n)
        joint = doc["skins"][0]["joints"][-1]
        first = len(nodes)
        if op == "skinned_nodes":
            nodes += [{"mesh": skinned["mesh"], "skin": skinned["skin"]} for _ in range(k // 10)]
        else:
            nodes += [{"mesh": skinned["mesh"], "children": [first + i + 1]} for i in range(k // 10 - 1)]
            nodes.append({"mesh": skinned["mesh"]})
            nodes[joint].setdefault("children", []).append(first)
    else:  # a chain of k ancestors above the skeleton's root
        root = doc["skins"][0]["joints"][0]
        parents = {c: i for i, n in enumerate(nodes) for c in n.get("children", [])}
        while root in parents:
            root = parents[root]
        for n in nodes:  # detach the root from any scene-less parent
            n["children"] = [c for c in n.get("children", []) if c != root]
        first = len(nodes)
        nodes += [{"name": f"up{i}", "children": [first + i + 1]} for i in range(k - 1)]
        nodes.append({"name": f"up{k - 1}", "children": [root]})


def _edit_key_times(rng, doc: dict, binary: bytearray) -> None:
    """One key time of an animation input becomes huge, infinite, NaN or out of order."""
    anims = _objects(doc, "animations")
    if not anims:
        return
    s = _pick(rng, _pick(rng, anims).get("samplers", [{}]) or [{}])
    accs, views = _objects(doc, "accessors"), _objects(doc, "bufferViews")
    a = accs[s["input"]] if isinstance(s.get("input"), int) and s["input"] < len(accs) else None
    if a is None or "bufferView" not in a:
        return
    v = views[a["bufferView"]]
    start = v.get("byteOffset", 0) + a.get("byteOffset", 0)
    k = _pick(rng, [a["count"] - 1, int(rng.integers(a["count"]))])
    value = _pick(rng, [1e5, 1e9, 3e38, np.inf, np.nan, -1e5, 700.0, 1e4])
    binary[start + 4 * k : start + 4 * k + 4] = np.float32(value).tobytes()


def _container_mutation(rng, data: bytes) -> tuple[str, bytes]:
    kind = _pick(rng, ["truncate", "flip", "header"])
    b = bytearray(data)
    if kind == "truncate":
        return kind, bytes(b[: int(rng.integers(len(b)))])
    if kind == "flip":
        for _ in range(int(rng.integers(1, 9))):
            i = int(rng.integers(len(b)))
            b[i] ^= 1 << int(rng.integers(8))
        return kind, bytes(b)
    field_ = int(rng.integers(5))  # magic, version, length, first chunk length, first chunk type
    offs = [0, 4, 8, 12, 16][field_]
    b[offs : offs + 4] = struct.pack("<I", int(_pick(rng, [0, 1, 3, 2**31, 2**32 - 1, len(b) + 8])))
    return kind, bytes(b)


# -- .gltf with external files: URIs --------------------------------------------------------

_URIS = [
    ("../secret.bin", True),
    ("sub/../../secret.bin", True),
    ("%2E%2E/secret.bin", True),
    ("link_out.bin", True),
    ("ABSOLUTE", True),
    ("file:///etc/passwd", True),
    ("http://127.0.0.1:9/x.bin", True),
    ("/etc/passwd", True),
    ("../../../../etc/passwd", True),
    ("data:,", False),
    ("data:application/octet-stream;base64,!!!", False),
    ("missing.bin", False),
    ("", False),
    (".", False),
    ("sub", False),
    ("sub/inside.bin", False),
    ("link_in.bin", False),
]


def _uri_case(rng, folder: Path, i: int) -> Case:
    doc, binary = tiny_gltf()
    uri, escapes = _pick(rng, _URIS)
    target = _pick(rng, ["buffer", "image"])
    folder.mkdir(parents=True)
    (folder / "sub").mkdir()
    (folder / "sub" / "inside.bin").write_bytes(binary)
    (folder / "m.bin").write_bytes(binary)
    (folder / "link_in.bin").symlink_to(folder / "m.bin")
    (folder / "link_out.bin").symlink_to(folder.parent / "secret.bin")
    if uri == "ABSOLUTE":
        uri = str(folder.parent / "secret.bin")
    doc["buffers"][0]["uri"] = "m.bin"
    if target == "buffer":
        doc["buffers"][0]["uri"] = uri
    else:
        # a textured mesh whose image URI is the edit; the buffer itself is fine
        doc, binary = with_texture(doc, binary, uri)
        (folder / "m.bin").write_bytes(binary)
    path = folder / "m.gltf"
    path.write_text(json.dumps(doc))
    # the image of a secret is a valid PNG: an escaping image URI would import "successfully"
    return Case(f"{i:04d}_uri_{target}", f"uri_{target}", path, must_fail=escapes)


# -- sizes declared in files, and files that are not files ---------------------------------------

BIG = 16 * 1024**3  # a sparse file's size: no disk taken, gigabytes to whoever reads it whole


def _special(p: Path, how: str) -> str:
    """Make ``p`` a FIFO, a socket or a device (a link to /dev/zero without root); returns what."""
    import socket

    if how == "socket" and len(str(p)) < 100:  # AF_UNIX paths are short
        s = socket.socket(socket.AF_UNIX)
        s.bind(str(p))
        s.close()
        return how
    if how == "device":
        try:
            os.mknod(p, 0o600 | 0o020000, os.makedev(1, 5))  # /dev/zero's own node
            return how
        except PermissionError:
            how = "dev_zero"
    if how == "dev_zero":
        p.symlink_to("/dev/zero")
        return how
    os.mkfifo(p)
    return "fifo"


SIZE_KINDS = ["special_model", "special_buffer", "sparse_model", "sparse_buffer", "sparse_gltf", "length"]
SPECIALS = ["fifo", "socket", "device", "dev_zero"]


def size_case(rng, folder: Path, i: int, kind: str | None = None, how: str | None = None) -> Case:
    """A model that must be refused unread: it is (or its buffer is) a FIFO, a socket or a device
    (``how``), a sparse 16 GB file, or it declares a buffer of a terabyte (``kind``: one of
    `SIZE_KINDS`; random when None)."""
    doc, binary = tiny_gltf()
    kind = _pick(rng, SIZE_KINDS) if kind is None else kind
    folder.mkdir(parents=True)
    how = _pick(rng, SPECIALS) if how is None else how
    if kind == "special_model":
        path = folder / "m.glb"
        how = _special(path, how)
        return Case(f"{i:04d}_{kind}_{how}", kind, path, must_fail=True)
    path = folder / ("m.glb" if kind == "sparse_model" else "m.gltf")
    if kind in ("sparse_model", "sparse_gltf"):
        path.write_bytes(glb_bytes(doc, binary) if kind == "sparse_model" else json.dumps(doc).encode())
        with open(path, "r+b") as f:
            f.truncate(BIG)
        return Case(f"{i:04d}_{kind}", kind, path, must_fail=True)
    doc["buffers"][0]["uri"] = "m.bin"
    name = kind
    if kind == "special_buffer":
        name = f"{kind}_{_special(folder / 'm.bin', how)}"
    else:
        (folder / "m.bin").write_bytes(binary)
        if kind == "sparse_buffer":
            with open(folder / "m.bin", "r+b") as f:
                f.truncate(BIG)
        else:
            doc["buffers"][0]["byteLength"] = _pick(rng, [2**40, 2**34, 10**18])
    path.write_text(json.dumps(doc))
    return Case(f"{i:04d}_{name}", kind, path, must_fail=True)


# -- USD mutations ----------------------------------------------------------------------------


_ARCS = {
    "sublayer": "#usda 1.0\n(\n    subLayers = [@{p}@]\n)\n",
    "reference": '#usda 1.0\ndef "A" (\n    prepend references = @{p}@\n)\n{{\n}}\n',
    "payload": '#usda 1.0\ndef "A" (\n    payload = @{p}@\n)\n{{\n}}\n',
    "variant_payload": (
        '#usda 1.0\ndef "A" (\n    variants = {{\n        string v = "x"\n    }}\n    prepend variantSets = "v"\n)\n'
        '{{\n    variantSet "v" = {{\n        "x" (\n            payload = @{p}@\n        ) {{\n        }}\n    }}\n}}\n'
    ),
}


def _usd_arc_escape(rng, text: str, folder: Path) -> tuple[str, str]:
    """A layer whose only content is an arc to the whole (valid) seed asset outside its folder:
    importing anything from it means the outside file was opened."""
    outside = folder.parent / f"outside_{folder.name}.usda"
    outside.write_text(text)
    how = _pick(rng, ["absolute", "dotdot", "symlink"])
    target = {"absolute": str(outside), "dotdot": f"../{outside.name}", "symlink": "./inside.usda"}[how]
    if how == "symlink":
        (folder / "inside.usda").symlink_to(outside)
    arc = _pick(rng, sorted(_ARCS))
    return f"arc_{arc}_{how}", _ARCS[arc].format(p=target)


def _usd_mutation(rng, text: str, folder: Path) -> tuple[str, str]:
    kind = _pick(rng, ["joints", "sublayer", "missing_attr", "values", "time", "text_noise", "arc"])
    lines = text.splitlines()
    if kind == "arc":
        return _usd_arc_escape(rng, text, folder)
    if kind == "joints":
        m = re.search(r"uniform token\[\] joints = \[(.*?)\]", text)
        if m:
            js = [j.strip() for j in m.group(1).split(",")]
            op = _pick(rng, ["dup", "reverse", "swap", "unknown", "empty"])
            if op == "dup":
                js.insert(int(rng.integers(len(js))), _pick(rng, js))
            elif op == "reverse":
                js = js[::-1]
            elif op == "swap" and len(js) > 1:
                a, b = rng.choice(len(js), 2, replace=False)
                js[a], js[b] = js[b], js[a]
            elif op == "unknown":
                js.append('"nowhere/else"')
            else:
                js = []
            text = text[: m.start(1)] + ", ".join(js) + text[m.end(1) :]
    elif kind == "sublayer":
        op = _pick(rng, ["self", "cycle", "missing", "absolute", "escape", "garbage"])
        name = {"self": "m.usda", "missing": "nothere.usda", "absolute": "/etc/passwd"}.get(op, "other.usda")
        if op == "escape":
            name = "../secret.usda"
            (folder.parent / "secret.usda").write_text("#usda 1.0\n")
        if op == "cycle":
            (folder / "other.usda").write_text("#usda 1.0\n(\n    subLayers = [@m.usda@]\n)\n")
        if op == "garbage":
            (folder / "other.usda").write_bytes(bytes(rng.integers(0, 256, 64, dtype=np.uint8)))
        text = text.replace("#usda 1.0\n(\n", f"#usda 1.0\n(\n    subLayers = [@{name}@]\n", 1)
    elif kind == "missing_attr":
        keys = [
            "points",
            "faceVertexIndices",
            "faceVertexCounts",
            "jointIndices",
            "jointWeights",
            "bindTransforms",
            "restTransforms",
            "skel:skeleton",
            "timeCodesPerSecond",
        ]
        key = _pick(rng, keys)
        lines = [ln for ln in lines if key not in ln]
        text = "\n".join(lines) + "\n"
    elif kind == "values":
        op = _pick(rng, ["nan_point", "index", "element_size", "tcps", "weights"])
        if op == "nan_point":
            text = _bad_first_value(text, rng, "point3f[] points = [(", r"[^,]*", ["nan", "inf", "1e30"])
        elif op == "index":
            text = _bad_first_value(text, rng, "faceVertexIndices = [", r"\d+", ["-1", "99999", "4"])
        elif op == "element_size":
            text = text.replace(
                "elementSize = ", f"elementSize = {_pick(rng, ['0', '7', '-1', '100'])}  # ", 1
            )
        elif op == "tcps":
            text = text.replace(
                "timeCodesPerSecond = ", f"timeCodesPerSecond = {_pick(rng, ['0', '-1', '1e-9'])}  # ", 1
            )
        else:
            text = _bad_first_value(text, rng, "jointWeights = [", r"[^,\]]*", ["nan", "-1", "0", "1e38"])
    elif kind == "time":
        keys = re.findall(r"^\s+(\d+): \[", text, flags=re.M)
        if keys:
            k = _pick(rng, keys)
            big = _pick(rng, ["100000", "10000000", "1e15", "-100000"])
            text = re.sub(rf"^(\s+){k}: \[", rf"\g<1>{big}: [", text, count=1, flags=re.M)
    else:
        b = bytearray(text.encode())
        op = _pick(rng, ["flip", "truncate", "delete_line"])
        if op == "flip":
            for _ in range(int(rng.integers(1, 6))):
                i = int(rng.integers(len(b)))
                b[i] = int(_pick(rng, list(b'(){}[]"@=,;#0x \n')))
        elif op == "truncate":
            b = b[: int(rng.integers(len(b)))]
        else:
            ls = b.split(b"\n")
            del ls[int(rng.integers(len(ls)))]
            b = bytearray(b"\n".join(ls))
        text = b.decode("utf-8", errors="replace")
    return kind, text


# -- generation ---------------------------------------------------------------------------------


def mutants(workdir: Path, n: int, seed: int = 18) -> list[Case]:
    """Write ``n`` mutated files under ``workdir`` (each in its own folder) and return them.

    The mix: 50% glTF/GLB JSON or binary edits, 15% GLB container damage, 10% URI edits of a
    .gltf with external files, 20% USD edits (glTF only when pxr is missing), 5% models that are
    (or whose buffer is) a FIFO, socket, device or sparse 16 GB file, or declare a huge buffer."""
    rng = np.random.default_rng(seed)
    workdir.mkdir(parents=True, exist_ok=True)
    (workdir / "secret.bin").write_bytes(_secret_png())
    docs = _seed_docs()
    usd = _usd_seeds(workdir)
    cases = []
    for i in range(n):
        r = rng.random()
        folder = workdir / f"m{i:04d}"
        if r < 0.10:
            cases.append(_uri_case(rng, folder, i))
            continue
        if r >= 0.95:
            cases.append(size_case(rng, folder, i))
            continue
        folder.mkdir(parents=True)
        if r < 0.30 and usd:
            name, text = _pick(rng, usd)
            kind, text = _usd_mutation(rng, text, folder)
            path = folder / "m.usda"
            path.write_text(text)
            arc = kind.startswith("arc_")
            cases.append(
                Case(f"{i:04d}_usd_{kind}_{name}", "usd_arc" if arc else f"usd_{kind}", path, must_fail=arc)
            )
            continue
        name, doc, binary = _pick(rng, docs)
        if r < 0.45:
            kind, data = _container_mutation(rng, glb_bytes(doc, binary))
            kind = f"glb_{kind}"
        else:
            doc = copy.deepcopy(doc)
            b = bytearray(binary)
            kind = _json_mutation(rng, doc, b)
            data = glb_bytes(doc, bytes(b))
        path = folder / "m.glb"
        path.write_bytes(data)
        cases.append(Case(f"{i:04d}_{kind}_{name}", kind, path))
    return cases


def _secret_png() -> bytes:
    """A file outside the model folders that is both a valid image and a valid buffer prefix."""
    import io

    from PIL import Image

    buf = io.BytesIO()
    Image.new("RGB", (4, 4), (255, 0, 0)).save(buf, format="PNG")
    doc, binary = tiny_gltf()
    return buf.getvalue() + SECRET + binary  # long enough to pass as the tiny buffer


# -- running ----------------------------------------------------------------------------------


def store_hashes(root: Path) -> dict[str, str]:
    """sha256 of every file under the store (the lock file aside: taking the lock may create it)."""
    out = {}
    for p in sorted(root.rglob("*")):
        if p.is_file() and not p.name.endswith(".lock"):
            out[str(p.relative_to(root))] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def _changed(before: dict[str, str], after: dict[str, str], added: str | None) -> list[str]:
    """Files that differ, apart from what adding asset ``added`` legitimately writes."""
    mine = set()
    if added:
        mine = {f"bank/assets/{added}.h5", f"bank/assets/{added}.json", "bank/index.json"}
    keys = set(before) | set(after)
    return sorted(k for k in keys if k not in mine and before.get(k) != after.get(k))


def _index_others_same(root: Path, before_index: dict, added: str) -> bool:
    after = json.loads((root / "bank" / "index.json").read_text())
    a = {k: v for k, v in after.get("assets", {}).items() if k != added}
    return a == before_index.get("assets", {})


def _worker() -> None:
    """Import the cases named on stdin, one JSON line each; answer one JSON line per case."""
    os.environ.setdefault("ZOOCTL_VIEWS", "0")
    import resource

    cap = int(
        os.environ.get("FUZZ_WORKER_AS_BYTES", str(8 * 1024**3))
    )  # a runaway case dies, not the machine
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    from zooctl.errors import ZooctlError
    from zooctl.pipelines.bank_import import add_files
    from zooctl.store.bank import Bank

    for line in sys.stdin:
        req = json.loads(line)
        root = Path(req["store"])
        bank = Bank.open(root)
        before = store_hashes(root)
        before_index = json.loads((root / "bank" / "index.json").read_text())
        try:
            Path("/proc/self/clear_refs").write_text("5")  # restart the peak-RSS count
        except OSError:
            pass
        t = time.perf_counter()
        res: dict = {}
        try:
            r = add_files(bank, [Path(req["path"])], name=req["name"], views=False)[0]
            if r.error is None:
                res = {"status": "ok"}
            else:
                res = {"status": "error", "message": r.error.message, "hint": r.error.hint or ""}
        except ZooctlError as exc:  # add_files keeps these per file; a raise here is still clear
            res = {"status": "error", "message": exc.message, "hint": exc.hint or ""}
        except MemoryError:
            res = {"status": "memory", "message": "MemoryError"}
        except BaseException as exc:  # noqa: BLE001 - the fuzz records what escaped
            res = {"status": "internal", "message": f"{type(exc).__name__}: {exc}"[:500]}
        res["seconds"] = time.perf_counter() - t
        res["peak_kb"] = _hwm_kb()
        after = store_hashes(root)
        added = req["name"] if res["status"] == "ok" else None
        res["changed"] = _changed(before, after, added)
        if added:
            if not _index_others_same(root, before_index, added):
                res["changed"].append("bank/index.json (other entries)")
            try:
                bank.remove(added)
            except ZooctlError as exc:
                res["changed"].append(f"remove failed: {exc.message}")
        sys.stdout.write(json.dumps(res) + "\n")
        sys.stdout.flush()


def _hwm_kb() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1])
    return 0


class _Worker:
    def __init__(self):
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join([str(REPO), str(TESTS), env.get("PYTHONPATH", "")])
        env.setdefault("OMP_NUM_THREADS", "1")
        env["ZOOCTL_VIEWS"] = "0"
        self.p = subprocess.Popen(
            [sys.executable, str(Path(__file__).resolve()), "--worker"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )

    def ask(self, req: dict, timeout: float) -> dict | None:
        """The worker's answer, or None when it died or took longer than ``timeout`` (killed)."""
        self.p.stdin.write(json.dumps(req) + "\n")
        self.p.stdin.flush()
        ready, _, _ = select.select([self.p.stdout], [], [], timeout)
        line = self.p.stdout.readline() if ready else ""
        if not line:
            self.close()
            return None
        return json.loads(line)

    def close(self) -> None:
        if self.p.poll() is None:
            self.p.kill()
        self.p.wait()
        self.p.stdin.close()
        self.p.stdout.close()
        self.p.stderr.close()


def _clear(message: str, hint: str) -> bool:
    """One short line saying what is wrong (and one for the hint), no internal failure."""
    return (
        bool(message)
        and "\n" not in message
        and "\n" not in hint
        and len(message) <= 600
        and "internal failure" not in message
        and "Traceback" not in message
    )


def _judge(case: Case, via: str, res: dict, died: str = "") -> Outcome:
    o = Outcome(
        case,
        via,
        res.get("status", "crash"),
        res.get("message", died),
        res.get("seconds", 0.0),
        res.get("peak_kb", 0),
    )
    if o.status == "error" and not _clear(res.get("message", ""), res.get("hint", "")):
        o.status = "unclear"
    if o.status == "ok" and case.must_fail:
        o.status = "breach"
    if o.passed and o.peak_kb > MAX_RSS_KB:
        o.status, o.detail = "memory", f"peak {o.peak_kb} kB; {o.detail}"
    if o.passed and res.get("changed"):
        o.status, o.detail = "store_changed", f"{res['changed'][:3]}; {o.detail}"
    return o


def run_library(cases: list[Case], store: Path, log=None) -> list[Outcome]:
    """Import each case through `add_files` in a worker process (restarted after a hang or crash)."""
    out = []
    w = _Worker()
    try:
        for k, case in enumerate(cases):
            t = time.perf_counter()
            res = w.ask({"store": str(store), "path": str(case.path), "name": f"fuzz{k}"}, TIMEOUT_S)
            if res is None:
                timed_out = time.perf_counter() - t >= TIMEOUT_S - 0.5
                err = w.p.stderr.read()[-300:] if not timed_out else ""
                res = {"status": "hang" if timed_out else "crash", "seconds": time.perf_counter() - t}
                out.append(_judge(case, "library", res, died=err))
                w = _Worker()
            else:
                out.append(_judge(case, "library", res))
            if log:
                log(out[-1])
    finally:
        w.close()
    return out


def run_cli(cases: list[Case], store: Path, log=None) -> list[Outcome]:
    """Import each case with the real `zooctl bank add` in its own process."""
    import tempfile
    import threading

    env = dict(os.environ)
    env.update({"ZOOCTL_VIEWS": "0", "COLUMNS": "200", "NO_COLOR": "1", "OMP_NUM_THREADS": "1"})
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), env.get("PYTHONPATH", "")])
    env.pop("ZOOCTL_DEBUG", None)
    out = []
    for k, case in enumerate(cases):
        name = f"cli{k}"
        before = store_hashes(store)
        before_index = json.loads((store / "bank" / "index.json").read_text())
        cmd = [sys.executable, "-m", "zooctl", "--store", str(store), "bank", "add", str(case.path)]
        t = time.perf_counter()
        with tempfile.TemporaryFile("w+") as errf:
            p = subprocess.Popen(
                [*cmd, "--name", name, "--no-views"],
                stdout=subprocess.DEVNULL,
                stderr=errf,
                env=env,
                cwd=REPO,
            )
            timer = threading.Timer(TIMEOUT_S, p.kill)
            timer.start()
            _, status, ru = os.wait4(p.pid, 0)  # wait4: this child's own peak RSS
            timer.cancel()
            p.returncode = os.waitstatus_to_exitcode(status)
            errf.seek(0)
            err = errf.read()
        res = {"seconds": time.perf_counter() - t, "peak_kb": int(ru.ru_maxrss)}
        lines = [ln for ln in err.strip().splitlines() if ln.strip()]
        if res["seconds"] >= TIMEOUT_S:
            res["status"] = "hang"
        elif p.returncode == 0:
            res["status"] = "ok"
        elif p.returncode == 2 and lines and lines[0].startswith("error: "):
            hint = lines[1].strip() if len(lines) > 1 else ""
            res.update(status="error", message=lines[0][7:], hint=hint)
            if len(lines) > 2 or (hint and not hint.startswith("hint:")):
                res.update(status="unclear", message=" | ".join(lines)[:500])
        else:
            res.update(status="internal", message=f"exit {p.returncode}: {' | '.join(lines)[:500]}")
        after = store_hashes(store)
        added = name if res["status"] == "ok" else None
        res["changed"] = _changed(before, after, added)
        if added:
            if not _index_others_same(store, before_index, added):
                res["changed"].append("bank/index.json (other entries)")
            from zooctl.store.bank import Bank

            Bank.open(store).remove(added)
        out.append(_judge(case, "cli", res))
        if log:
            log(out[-1])
    return out


def make_store(root: Path) -> str:
    """A scratch store holding one valid asset, the 'other stored data' a failed import must keep."""
    from zooctl.io.gltf_import import load_gltf
    from zooctl.store.bank import Bank

    root.mkdir(parents=True, exist_ok=True)
    seed = root.parent / "base.glb"
    seed.write_bytes(glb_bytes(*tiny_gltf()))
    Bank.open(root).add(load_gltf(seed, "base"))
    return "base"


def summarize(outcomes: list[Outcome]) -> dict:
    counts: dict[str, int] = {}
    for o in outcomes:
        counts[o.status] = counts.get(o.status, 0) + 1
    return counts


if __name__ == "__main__" and "--worker" in sys.argv:
    _worker()
