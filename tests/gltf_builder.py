"""Hand-built glTF files for tests (a two-bone rig), written from the spec."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np


def glb_bytes(doc: dict, binary: bytes) -> bytes:
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    binary += b"\0" * (-len(binary) % 4)
    body = struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(binary), 0x004E4942) + binary
    return struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body


def tiny_gltf(weights=None, joints=None, skin=True):
    """A two-bone, one-triangle-strip skinned glTF document built by hand."""
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float32)
    idx = np.array([0, 1, 2, 1, 3, 2], np.uint16)
    j = np.array(
        joints if joints is not None else [[0, 0, 0, 0], [0, 1, 0, 0], [1, 0, 0, 0], [1, 0, 0, 0]], np.uint16
    )
    w = np.array(
        weights if weights is not None else [[1, 0, 0, 0], [0.5, 0.5, 0, 0], [1, 0, 0, 0], [1, 0, 0, 0]],
        np.float32,
    )
    ibm = np.stack(
        [np.eye(4), np.linalg.inv(np.array([[1, 0, 0, 0], [0, 1, 0, 1], [0, 0, 1, 0], [0, 0, 0, 1.0]]))]
    ).astype(np.float32)
    times = np.array([0, 1], np.float32)
    rots = np.array([[0, 0, 0, 1], [0, 0, 0.7071068, 0.7071068]], np.float32)
    blobs = [
        pos.tobytes(),
        idx.tobytes() + b"\0\0",
        j.tobytes(),
        w.tobytes(),
        ibm.transpose(0, 2, 1).tobytes(),
        times.tobytes(),
        rots.tobytes(),
    ]
    views, off = [], 0
    for b in blobs:
        views.append({"buffer": 0, "byteOffset": off, "byteLength": len(b)})
        off += len(b)
    binary = b"".join(blobs)
    accessors = [
        {
            "bufferView": 0,
            "componentType": 5126,
            "count": 4,
            "type": "VEC3",
            "min": [0, 0, 0],
            "max": [1, 1, 0],
        },
        {"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"},
        {"bufferView": 2, "componentType": 5123, "count": 4, "type": "VEC4"},
        {"bufferView": 3, "componentType": 5126, "count": 4, "type": "VEC4"},
        {"bufferView": 4, "componentType": 5126, "count": 2, "type": "MAT4"},
        {"bufferView": 5, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0], "max": [1]},
        {"bufferView": 6, "componentType": 5126, "count": 2, "type": "VEC4"},
    ]
    prim = {"attributes": {"POSITION": 0, "JOINTS_0": 2, "WEIGHTS_0": 3}, "indices": 1}
    nodes = [
        {"name": "mesh", "mesh": 0, **({"skin": 0} if skin else {})},
        {"name": "root", "children": [2]},
        {"name": "tip", "translation": [0, 1, 0]},
    ]
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0, 1]}],
        "nodes": nodes,
        "meshes": [{"primitives": [prim]}],
        "skins": [{"joints": [1, 2], "inverseBindMatrices": 4}] if skin else [],
        "animations": [
            {
                "name": "bend",
                "channels": [{"sampler": 0, "target": {"node": 2, "path": "rotation"}}],
                "samplers": [{"input": 5, "output": 6}],
            }
        ],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": len(binary)}],
    }
    return doc, binary


def write_tiny_glb(path: Path, **kw) -> Path:
    doc, binary = tiny_gltf(**kw)
    path.write_bytes(glb_bytes(doc, binary))
    return path


def with_texture(doc, binary, image_uri):
    """Add UVs, a material with a base-colour texture and an image at ``image_uri``."""
    uv = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], np.float32).tobytes()
    doc["bufferViews"].append({"buffer": 0, "byteOffset": len(binary), "byteLength": len(uv)})
    doc["accessors"].append(
        {"bufferView": len(doc["bufferViews"]) - 1, "componentType": 5126, "count": 4, "type": "VEC2"}
    )
    binary = binary + uv
    doc["buffers"][0]["byteLength"] = len(binary)
    prim = doc["meshes"][0]["primitives"][0]
    prim["attributes"]["TEXCOORD_0"] = len(doc["accessors"]) - 1
    prim["material"] = 0
    doc["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
    doc["textures"] = [{"source": 0}]
    doc["images"] = [{"uri": image_uri}]
    return doc, binary
