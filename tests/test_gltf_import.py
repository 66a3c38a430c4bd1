"""glTF import against an independent reader on the 28 shared assets, and bad-input handling."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import needs_shared_assets, shared_assets
from gltf_builder import glb_bytes as _glb
from gltf_builder import tiny_gltf
from gltf_reference import Reference

from zooctl.errors import InputError
from zooctl.io.gltf_import import load_gltf


@needs_shared_assets
@pytest.mark.parametrize("path", shared_assets(), ids=lambda p: p.stem)
def test_posed_vertices_match_independent_reader(path):
    asset = load_gltf(path, path.stem)
    ref = Reference(path)
    tol = 1e-5 * asset.size()
    # rest pose
    want = ref.skinned_vertices(None, 0.0)
    ok = np.isfinite(want).all(1)  # the reference has no repair for NaN-weighted vertices
    assert asset.num_vertices == len(want)
    np.testing.assert_allclose(asset.pose()[ok], want[ok], atol=tol)
    rng = np.random.default_rng(0)
    for clip_name in list(asset.clips)[:4]:
        clip = asset.clips[clip_name]
        anim = next(a for a in ref.g["animations"] if a.get("name") == clip_name)
        t0 = ref.anim_start(anim)
        frames = sorted({0, clip.num_frames - 1, int(rng.integers(clip.num_frames))})
        posed = asset.pose(clip_name, np.array(frames))
        for k, f in enumerate(frames):
            want = ref.skinned_vertices(clip_name, t0 + f / clip.fps)
            np.testing.assert_allclose(posed[k][ok], want[ok], atol=tol, err_msg=f"{clip_name} frame {f}")


@needs_shared_assets
def test_every_shared_asset_imports_with_clips():
    for path in shared_assets():
        a = load_gltf(path, path.stem)
        assert a.num_joints >= 6 and a.num_vertices > 500 and a.clips, path.stem
        assert np.allclose(a.skin_weights.sum(1), 1, atol=1e-5)


def test_tiny_asset_poses_as_expected(tmp_path):
    doc, binary = tiny_gltf()
    p = tmp_path / "tiny.glb"
    p.write_bytes(_glb(doc, binary))
    a = load_gltf(p, "tiny", fps=4)
    assert a.joint_names == ["root", "tip"] and list(a.parents) == [-1, 0]
    assert a.clips["bend"].num_frames == 5
    end = a.pose("bend", 4)
    # vertex 2 sits on the tip joint with weight 1 and rotates 90 deg about z around it: stays put
    np.testing.assert_allclose(end[2], [0, 1, 0], atol=1e-6)
    # vertex 3 (1, 1, 0) rotates about the tip (0, 1, 0) by 90 deg: -> (0, 2, 0)
    np.testing.assert_allclose(end[3], [0, 2, 0], atol=1e-6)


def test_gltf_with_external_bin(tmp_path):
    doc, binary = tiny_gltf()
    doc["buffers"][0]["uri"] = "tiny.bin"
    (tmp_path / "tiny.gltf").write_text(json.dumps(doc))
    (tmp_path / "tiny.bin").write_bytes(binary)
    a = load_gltf(tmp_path / "tiny.gltf", "tiny")
    assert a.num_vertices == 4
    (tmp_path / "tiny.bin").unlink()
    with pytest.raises(InputError, match="missing"):
        load_gltf(tmp_path / "tiny.gltf", "tiny")


@pytest.mark.parametrize(
    "case,match",
    [
        ("empty", "empty"),
        ("truncated", "truncated"),
        ("noskin", "no skin"),
        ("nan", "NaN"),
        ("negative", "negative"),
        ("joint_range", "out of range"),
        ("directory", "directory"),
        ("garbage", "not a GLB"),
    ],
)
def test_bad_input_is_a_clear_error(tmp_path, case, match):
    p = tmp_path / "bad.glb"
    if case == "empty":
        p.write_bytes(b"")
    elif case == "truncated":
        doc, binary = tiny_gltf()
        p.write_bytes(_glb(doc, binary)[:-40])
    elif case == "noskin":
        doc, binary = tiny_gltf(skin=False)
        p.write_bytes(_glb(doc, binary))
    elif case == "nan":
        doc, binary = tiny_gltf(weights=[[np.nan, 0, 0, 0]] * 4)
        p.write_bytes(_glb(doc, binary))
    elif case == "negative":
        doc, binary = tiny_gltf(weights=[[1.5, -0.5, 0, 0]] * 4)
        p.write_bytes(_glb(doc, binary))
    elif case == "joint_range":
        doc, binary = tiny_gltf(joints=[[7, 0, 0, 0]] * 4)
        p.write_bytes(_glb(doc, binary))
    elif case == "directory":
        p = tmp_path / "dir.glb"
        p.mkdir()
    elif case == "garbage":
        p.write_bytes(b"hello world, this is not a model at all")
    with pytest.raises(InputError, match=match):
        load_gltf(p, "bad")
