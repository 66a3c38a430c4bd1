"""glTF import against an independent reader on the 28 shared assets, and bad-input handling."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import needs_shared_assets, shared_assets
from gltf_builder import glb_bytes as _glb
from gltf_builder import tiny_gltf, with_texture
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


# -- malformed files (issue 18): each is one clear InputError, never an internal failure --------


def _times(doc, binary, times):
    """Replace the tiny clip's two key times (accessor 5) in the binary blob."""
    view = doc["bufferViews"][doc["accessors"][5]["bufferView"]]
    off = view["byteOffset"]
    return binary[:off] + np.asarray(times, np.float32).tobytes() + binary[off + 8 :]


def _edit(case):
    doc, binary = tiny_gltf()
    if case == "negative_count":
        doc["accessors"][0]["count"] = -5
    elif case == "negative_offset":
        doc["bufferViews"][0]["byteOffset"] = -16
    elif case == "string_count":
        doc["accessors"][0]["count"] = "4"
    elif case == "cubicspline_count":
        doc["animations"][0]["samplers"][0]["interpolation"] = "CUBICSPLINE"
    elif case == "rotation_width":
        doc["accessors"][6]["type"] = "VEC3"
    elif case == "times_backwards":
        binary = _times(doc, binary, [1, 0])
    elif case == "zero_scale_ancestor":
        doc["nodes"].append({"name": "Armature", "scale": [0, 0, 0], "children": [1]})
    elif case == "zero_scale_root_joint":
        doc["nodes"][1]["scale"] = [0, 0, 0]
    elif case == "singular_matrix":
        doc["nodes"].append({"name": "Armature", "matrix": [1, 0, 0, 0] * 3 + [0, 0, 0, 1], "children": [1]})
    elif case == "node_cycle":
        doc["nodes"][2]["children"] = [1]
    elif case == "self_child":
        doc["nodes"][2]["children"] = [2]
    elif case == "nodes_not_array":
        doc["nodes"] = {"0": {}}
    elif case == "bad_skin_index":
        doc["nodes"][0]["skin"] = "zero"
    elif case == "huge_count_no_view":
        del doc["accessors"][3]["bufferView"]
        doc["accessors"][3]["count"] = 10**12
    elif case == "nan_translation":
        doc["nodes"][2]["translation"] = [0, float("nan"), 0]
    elif case == "missing_byte_length":
        del doc["bufferViews"][1]["byteLength"]
    return doc, binary


@pytest.mark.parametrize(
    "case,match",
    [
        ("negative_count", "count -5"),
        ("negative_offset", "byteOffset -16"),
        ("string_count", "count '4'"),
        ("cubicspline_count", "expected 6 of 4"),
        ("rotation_width", "expected 2 of 4"),
        ("times_backwards", "go backwards"),
        ("zero_scale_ancestor", "'Armature' is singular"),
        ("zero_scale_root_joint", "collapses to a single point"),
        ("singular_matrix", "singular or sheared"),
        ("node_cycle", "cycle"),
        ("self_child", "not a tree|cycle"),
        ("nodes_not_array", "'nodes' must be an array"),
        ("bad_skin_index", "skins\\['zero'\\]"),
        ("huge_count_no_view", "over the import limit"),
        ("nan_translation", "NaN"),
        ("missing_byte_length", "no byteLength"),
    ],
)
def test_malformed_gltf_is_one_clear_error(tmp_path, case, match):
    doc, binary = _edit(case)
    p = tmp_path / f"{case}.glb"
    p.write_bytes(_glb(doc, binary))
    with pytest.raises(InputError, match=match) as err:
        load_gltf(p, "bad")
    assert "\n" not in err.value.message


def test_keyframe_far_in_time_is_refused_unless_the_limit_is_raised(tmp_path):
    from zooctl.limits import import_limits

    doc, binary = tiny_gltf()
    p = tmp_path / "long.glb"
    p.write_bytes(_glb(doc, _times(doc, binary, [0, 1000])))
    with pytest.raises(InputError, match="lasts 1,000 s, over the import limit of 600 s") as err:
        load_gltf(p, "long")
    assert "--max-clip-seconds" in err.value.hint
    with import_limits(max_clip_seconds=2000):
        a = load_gltf(p, "long", fps=30)
    assert a.clips["bend"].num_frames == 30001
    with (
        import_limits(max_clip_seconds=2000, max_frames=100),
        pytest.raises(InputError, match="30,001 frames"),
    ):
        load_gltf(p, "long")
    with (
        import_limits(max_clip_seconds=2000, max_elements=1000),
        pytest.raises(InputError, match="joint-frames"),
    ):
        load_gltf(p, "long")


def test_deep_node_chain_and_strips(tmp_path):
    """Thousands of ancestors do not overflow the stack; strips and fans keep their winding."""
    doc, binary = tiny_gltf()
    n0 = len(doc["nodes"])
    chain = [{"name": f"a{i}", "children": [n0 + i + 1 if i < 2999 else 1]} for i in range(3000)]
    doc["nodes"] += chain
    p = tmp_path / "deep.glb"
    p.write_bytes(_glb(doc, binary))
    a = load_gltf(p, "deep")
    assert a.num_joints == 3002 and a.joint_names[-2:] == ["root", "tip"]
    doc, binary = tiny_gltf()
    doc["meshes"][0]["primitives"][0].pop("indices")
    for mode, want in ((5, [[0, 1, 2], [2, 1, 3]]), (6, [[0, 1, 2], [0, 2, 3]])):
        doc["meshes"][0]["primitives"][0]["mode"] = mode
        p.write_bytes(_glb(doc, binary))
        assert load_gltf(p, "strip").faces.tolist() == want


# -- URIs stay inside the glTF file's folder (issue 18, security) ----------------------------------


def _png() -> bytes:
    import io

    from PIL import Image

    buf = io.BytesIO()
    Image.new("RGB", (2, 2), (200, 10, 10)).save(buf, format="PNG")
    return buf.getvalue()


@pytest.mark.parametrize(
    "uri,match",
    [
        ("../outside.bin", "outside the glTF file's folder"),
        ("sub/../../outside.bin", "outside the glTF file's folder"),
        ("%2E%2E/outside.bin", "outside the glTF file's folder"),
        ("link.bin", "outside the glTF file's folder"),  # a symlink out of the folder
        ("ABSOLUTE", "only relative file names and data URIs"),
        ("file:///etc/passwd", "only relative file names and data URIs"),
        ("https://example.com/x.bin", "only relative file names and data URIs"),
        ("loop.bin", "cannot be resolved|missing"),  # a symlink to itself
    ],
)
def test_buffer_uri_cannot_leave_the_folder(tmp_path, uri, match):
    doc, binary = tiny_gltf()
    folder = tmp_path / "model"
    folder.mkdir()
    (tmp_path / "outside.bin").write_bytes(binary)  # a readable file the URI must not reach
    (folder / "link.bin").symlink_to(tmp_path / "outside.bin")
    (folder / "loop.bin").symlink_to(folder / "loop.bin")
    doc["buffers"][0]["uri"] = str(tmp_path / "outside.bin") if uri == "ABSOLUTE" else uri
    (folder / "m.gltf").write_text(json.dumps(doc))
    with pytest.raises(InputError, match=match):
        load_gltf(folder / "m.gltf", "m")


def test_image_uris_are_checked_and_relative_files_work(tmp_path):
    import base64

    folder = tmp_path / "model"
    (folder / "tex").mkdir(parents=True)
    (tmp_path / "secret.png").write_bytes(_png())
    (folder / "tex" / "ok.png").write_bytes(_png())
    (folder / "tex" / "inside_link.png").symlink_to(folder / "tex" / "ok.png")
    for uri, ok in (("tex/ok.png", True), ("tex/inside_link.png", True), ("../secret.png", False)):
        doc, binary = with_texture(*tiny_gltf(), uri)
        doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(binary).decode()
        (folder / "m.gltf").write_text(json.dumps(doc))
        if ok:
            assert load_gltf(folder / "m.gltf", "m").texture_png == _png()
        else:
            with pytest.raises(InputError, match="image 0 refers to '../secret.png', which is outside"):
                load_gltf(folder / "m.gltf", "m")


def test_bank_add_limit_options(tmp_path, store, capsys):
    from cli_helpers import run_inprocess

    doc, binary = tiny_gltf()
    p = tmp_path / "long.glb"
    p.write_bytes(_glb(doc, _times(doc, binary, [0, 1000])))
    r = run_inprocess(capsys, "bank", "add", str(p))
    assert r.code == 2 and "over the import limit of 600 s" in r.err and "Traceback" not in r.err
    assert len(r.err.strip().splitlines()) == 2  # the error and its hint
    r = run_inprocess(capsys, "bank", "add", str(p), "--max-clip-seconds", "1200")
    assert r.code == 0, r.err
    r = run_inprocess(
        capsys, "bank", "add", str(p), "--name", "again", "--max-clip-seconds", "1200", "--max-frames", "10"
    )
    assert r.code == 2 and "--max-frames" in r.err
    r = run_inprocess(capsys, "bank", "add", str(p), "--name", "again", "--max-frames", "0")
    assert r.code == 2 and "must be positive" in r.err


def test_references_repeated_many_times_stay_bounded(tmp_path):
    """Thousands of primitives or channels naming the same accessors: limited (or deduplicated),
    not decoded and copied thousands of times."""
    from zooctl.limits import import_limits

    doc, binary = tiny_gltf()
    p = tmp_path / "many.glb"
    doc["meshes"][0]["primitives"] *= 3000
    p.write_bytes(_glb(doc, binary))
    assert load_gltf(p, "many").num_vertices == 12000
    with import_limits(max_vertices=1000), pytest.raises(InputError, match="1,000 vertices") as err:
        load_gltf(p, "many")
    assert "--max-vertices" in err.value.hint
    with (
        import_limits(max_elements=100),
        pytest.raises(InputError, match="read .* over the import limit of 400"),
    ):
        load_gltf(p, "many")
    doc, binary = tiny_gltf()
    want = load_gltf(_write(tmp_path / "one.glb", doc, binary), "one").clips["bend"].rotations
    doc["animations"][0]["channels"] *= 20000
    got = load_gltf(_write(p, doc, binary), "many").clips["bend"].rotations
    np.testing.assert_array_equal(got, want)


def _write(p, doc, binary):
    p.write_bytes(_glb(doc, binary))
    return p
