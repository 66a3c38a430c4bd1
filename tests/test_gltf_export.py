"""glTF binary export: the document is well formed, and importing it again gives the same posed
vertices for every clip frame (28 shared assets, every starter animal)."""

from __future__ import annotations

import io
import json
import struct

import numpy as np
import pytest
from conftest import needs_shared_assets, shared_assets

from zooctl.errors import UsageError
from zooctl.io.gltf_export import gltf_document, save_glb
from zooctl.io.gltf_import import load_gltf
from zooctl.io.rig_compare import posed_difference, posed_error_bound
from zooctl.procedural import build_animal, starter_assets

TOL = 1e-4  # of the model's size


def read_glb(path):
    data = path.read_bytes()
    magic, version, length = struct.unpack_from("<III", data)
    assert (magic, version, length) == (0x46546C67, 2, len(data))
    jlen, jtype = struct.unpack_from("<II", data, 12)
    assert jtype == 0x4E4F534A and jlen % 4 == 0
    doc = json.loads(data[20 : 20 + jlen])
    blen, btype = struct.unpack_from("<II", data, 20 + jlen)
    assert btype == 0x004E4942 and blen % 4 == 0
    return doc, data[28 + jlen : 28 + jlen + blen]


def check_document(doc, blob, asset) -> None:
    """Structural rules of glTF 2.0 that readers rely on."""
    assert doc["asset"]["version"] == "2.0"
    assert doc["buffers"][0]["byteLength"] <= len(blob)
    sizes = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
    comp = {5126: 4, 5125: 4, 5123: 2, 5121: 1}
    for acc in doc["accessors"]:
        view = doc["bufferViews"][acc["bufferView"]]
        assert view["byteOffset"] % 4 == 0
        assert acc["count"] * sizes[acc["type"]] * comp[acc["componentType"]] <= view["byteLength"]
        assert view["byteOffset"] + view["byteLength"] <= len(blob)
    prim = doc["meshes"][0]["primitives"][0]
    pos = doc["accessors"][prim["attributes"]["POSITION"]]
    assert pos["count"] == asset.num_vertices and "min" in pos and "max" in pos
    np.testing.assert_allclose(pos["min"], asset.vertices.min(0), rtol=1e-6)
    skin = doc["skins"][0]
    # Every weighted joint is a skin joint; unweighted roots may stay plain nodes above the skin.
    names = [doc["nodes"][j]["name"] for j in skin["joints"]]
    weighted = asset.skin_weights_dense().sum(0) > 0
    assert {asset.joint_names[j] for j in np.nonzero(weighted)[0]} <= set(names)
    assert len(names) <= asset.num_joints
    for anim in doc.get("animations", []):
        for ch in anim["channels"]:
            node = doc["nodes"][ch["target"]["node"]]
            assert "matrix" not in node  # animated nodes must use TRS
            sampler = anim["samplers"][ch["sampler"]]
            assert "min" in doc["accessors"][sampler["input"]]
    # Weights of every vertex sum to one (readers normalise nothing).
    total = np.zeros(asset.num_vertices)
    for k in range(4):
        if f"WEIGHTS_{k}" not in prim["attributes"]:
            break
        acc = doc["accessors"][prim["attributes"][f"WEIGHTS_{k}"]]
        view = doc["bufferViews"][acc["bufferView"]]
        w = np.frombuffer(blob, np.float32, acc["count"] * 4, view["byteOffset"]).reshape(-1, 4)
        total += w.sum(1)
    np.testing.assert_allclose(total, 1.0, atol=1e-5)


def check_round_trip(asset, path) -> None:
    save_glb(asset, path)
    check_document(*read_glb(path), asset)
    back = load_gltf(path, "back")
    assert list(back.clips) == list(asset.clips)
    size = asset.size()
    for name, clip in asset.clips.items():
        assert back.clips[name].num_frames == clip.num_frames
        fr = sorted({0, clip.num_frames // 2, clip.num_frames - 1})
        assert posed_difference(asset, back, name, fr) <= TOL * size, name
    # Every frame of every clip. (Not the rest pose: the file's nodes hold the bind pose.)
    assert posed_error_bound(asset, back, include_rest=False) <= TOL * size
    assert sorted(back.joint_names) == sorted(asset.joint_names)
    if asset.vertex_colors is not None:
        np.testing.assert_allclose(back.vertex_colors, asset.vertex_colors, atol=1e-6)


@needs_shared_assets
@pytest.mark.parametrize("path", shared_assets(), ids=lambda p: p.stem)
def test_shared_asset_glb_round_trip(path, tmp_path):
    check_round_trip(load_gltf(path, path.stem), tmp_path / "out.glb")


@pytest.mark.parametrize("asset", starter_assets(0), ids=lambda a: a.name)
def test_starter_animal_glb_round_trip(asset, tmp_path):
    check_round_trip(asset, tmp_path / f"{asset.name}.glb")


def test_selected_clips_only(tmp_path):
    asset = build_animal("quadruped")
    path = save_glb(asset, tmp_path / "q.glb", clips=["trot"])
    doc, _ = read_glb(path)
    assert [a["name"] for a in doc["animations"]] == ["trot"]
    assert list(load_gltf(path, "q").clips) == ["trot"]


def test_texture_and_uvs(tmp_path):
    from PIL import Image

    asset = build_animal("fish")
    v = asset.vertices
    asset.uvs = np.stack(
        [(v[:, 2] - v[:, 2].min()) / np.ptp(v[:, 2]), 1 - (v[:, 1] - v[:, 1].min()) / np.ptp(v[:, 1])], 1
    ).astype(np.float32)
    img = np.zeros((8, 8, 3), np.uint8)
    img[:, ::2] = (10, 120, 240)
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    asset.texture_png = buf.getvalue()
    path = save_glb(asset, tmp_path / "fish.glb")
    doc, blob = read_glb(path)
    assert doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["index"] == 0
    assert doc["images"][0]["mimeType"] == "image/png"
    back = load_gltf(path, "fish")
    np.testing.assert_allclose(back.uvs, asset.uvs, atol=1e-6)
    np.testing.assert_array_equal(np.asarray(Image.open(io.BytesIO(back.texture_png)).convert("RGB")), img)


def test_many_influences_use_a_second_joint_set(tmp_path):
    asset = build_animal("snake")
    dense = asset.skin_weights_dense()
    smooth = (
        dense
        + 0.02 * np.roll(dense, 1, axis=1)
        + 0.02 * np.roll(dense, -1, axis=1)
        + 0.01 * np.roll(dense, 2, axis=1)
    )
    from zooctl.asset import sparsify_weights

    asset.skin_joints, asset.skin_weights = sparsify_weights(smooth, 6)
    doc, blob = gltf_document(asset)
    assert {"JOINTS_1", "WEIGHTS_1"} <= set(doc["meshes"][0]["primitives"][0]["attributes"])
    check_round_trip(asset, tmp_path / "snake.glb")


def test_bad_requests_are_clear_errors(tmp_path):
    asset = build_animal("fish")
    with pytest.raises(UsageError, match="cannot write glTF binary"):
        save_glb(asset, tmp_path / "fish.gltf")
    with pytest.raises(UsageError, match="no clip 'fly'"):
        save_glb(asset, tmp_path / "fish.glb", clips=["fly"])
    assert not list(tmp_path.iterdir())
