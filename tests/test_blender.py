"""Blender (the PyPI ``bpy`` module, run headless in a subprocess) opens our USD and GLB exports:
an armature with the right bone count, actions over the right frames, and the vertices Blender
deforms at a frame are ours. Also FBX / COLLADA / BVH import through assimp, from files Blender
writes. A sample of assets keeps this fast; bpy is heavy and keeps global state, so it never
loads into the test process."""

from __future__ import annotations

import functools
import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from conftest import ASSETS_DIR

from zooctl.io.gltf_export import save_glb
from zooctl.io.usd_export import save_usd
from zooctl.procedural import build_animal

TOL = 1e-4  # of the model's size


@functools.lru_cache(maxsize=1)
def bpy_problem() -> str | None:
    """Why `import bpy` fails in this interpreter, or None when it works."""
    p = subprocess.run([sys.executable, "-c", "import bpy"], capture_output=True, text=True, timeout=300)
    return None if p.returncode == 0 else (p.stderr.strip().splitlines() or ["import failed"])[-1]


needs_bpy = pytest.mark.skipif(
    bpy_problem() is not None,
    reason=f"Blender's bpy module is not importable ({bpy_problem()}); `make install` installs bpy==4.2.0",
)

BLENDER_CHECK = textwrap.dedent("""
    import json, os, sys
    import bpy
    import numpy as np

    def run(job):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        scene = bpy.context.scene
        scene.render.fps = int(round(job["fps"]))
        if job["kind"] == "usd":
            bpy.ops.wm.usd_import(filepath=job["path"])
        else:
            bpy.ops.import_scene.gltf(filepath=job["path"])
        arms = [o for o in bpy.data.objects if o.type == "ARMATURE"]
        skinned = [o for o in bpy.data.objects if o.type == "MESH" and any(m.type == "ARMATURE" for m in o.modifiers)]
        out = {"armatures": len(arms), "bones": [len(a.data.bones) for a in arms], "skinned": len(skinned),
               "actions": {a.name: list(a.frame_range) for a in bpy.data.actions}}
        arm = arms[0]
        if job.get("action"):
            for track in list(arm.animation_data.nla_tracks):  # no other clip may blend in
                arm.animation_data.nla_tracks.remove(track)
            named = [a for a in bpy.data.actions if a.name == job["action"] or a.name.startswith(job["action"] + "_")]
            arm.animation_data.action = min(named, key=lambda a: len(a.name))  # "Idle_<armature>", not "Idle_2_..."
        out["action"] = arm.animation_data.action.name if arm.animation_data and arm.animation_data.action else None
        scene.frame_set(job["frame"])
        depsgraph = bpy.context.evaluated_depsgraph_get()
        points = []
        for obj in skinned:
            ev = obj.evaluated_get(depsgraph)
            mesh = ev.to_mesh()
            co = np.empty(len(mesh.vertices) * 3)
            mesh.vertices.foreach_get("co", co)
            mw = np.array(ev.matrix_world)
            points.append(co.reshape(-1, 3) @ mw[:3, :3].T + mw[:3, 3])
            ev.to_mesh_clear()
        np.save(job["out"], np.concatenate(points))
        return out

    results = [run(job) for job in json.loads(sys.argv[1])]
    print("RESULT" + json.dumps(results), flush=True)
    os._exit(0)  # bpy can crash while tearing down at interpreter exit
""")

BLENDER_WRITE = textwrap.dedent("""
    import os, sys
    import bpy
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.context.scene.render.fps = 30
    bpy.ops.import_scene.gltf(filepath=sys.argv[1])
    out = sys.argv[2]
    arm = next(o for o in bpy.data.objects if o.type == "ARMATURE")
    keep = [arm] + [o for o in bpy.data.objects if o.type == "MESH" and any(m.type == "ARMATURE" for m in o.modifiers)]
    bpy.ops.object.select_all(action="DESELECT")
    for o in keep:
        o.select_set(True)
    bpy.context.view_layer.objects.active = arm
    bpy.ops.export_scene.fbx(filepath=out + ".fbx", use_selection=True, bake_anim=True)
    bpy.ops.wm.collada_export(filepath=out + ".dae", selected=True)
    bpy.ops.object.select_all(action="DESELECT")
    arm.select_set(True)
    bpy.ops.export_anim.bvh(filepath=out + ".bvh", frame_start=0, frame_end=20)
    print("WROTE", flush=True)
    os._exit(0)
""")


def run_blender(script: str, *args: str) -> str:
    env = dict(os.environ, PYTHONNOUSERSITE="1")
    p = subprocess.run(
        [sys.executable, "-c", script, *args], capture_output=True, text=True, timeout=600, env=env
    )
    assert p.returncode == 0, p.stdout[-2000:] + p.stderr[-2000:]
    return p.stdout


def to_blender(points: np.ndarray) -> np.ndarray:
    """Our Y-up coordinates as Blender's Z-up world coordinates (both importers turn the scene)."""
    return np.stack([points[:, 0], -points[:, 2], points[:, 1]], 1)


def set_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Symmetric largest nearest-neighbour distance between two point sets (order-independent)."""
    from scipy.spatial import cKDTree

    return float(max(cKDTree(a).query(b)[0].max(), cKDTree(b).query(a)[0].max()))


def read_skin_joints(path) -> list[int]:
    import struct

    data = open(path, "rb").read()
    (jlen,) = struct.unpack_from("<I", data, 12)
    return json.loads(data[20 : 20 + jlen])["skins"][0]["joints"]


def sample_assets():
    from zooctl.io.gltf_import import load_gltf

    assets = [build_animal("quadruped")]
    # Blender's bones cannot inherit a non-uniform scale the way glTF and UsdSkel nodes do, so rigs
    # that rely on it (the shared Fox and Crab) deform slightly differently in Blender even from
    # their original files; the sample holds rigs Blender represents exactly.
    for rel in ("easy_enemies_pack/Snake.glb", "fish_pack/Fish1.glb", "cute_fish_pack/Koi.glb"):
        if (ASSETS_DIR / rel).is_file():
            assets.append(load_gltf(ASSETS_DIR / rel, (ASSETS_DIR / rel).stem))
    return assets


@needs_bpy
def test_blender_opens_usd_and_glb_exports(tmp_path):
    jobs, expect = [], []
    for asset in sample_assets():
        clips = list(asset.clips)
        first, other = clips[0], clips[-1]
        usd = save_usd(asset, tmp_path / f"{asset.name}.usdc")
        glb = save_glb(asset, tmp_path / f"{asset.name}.glb")
        f_usd = asset.clips[first].num_frames // 2
        f_glb = max(0, asset.clips[other].num_frames - 3)
        jobs.append(
            {
                "kind": "usd",
                "path": str(usd),
                "fps": asset.clips[first].fps,
                "frame": f_usd,
                "out": str(tmp_path / f"{asset.name}.usd.npy"),
            }
        )
        expect.append((asset, first, f_usd))
        jobs.append(
            {
                "kind": "glb",
                "path": str(glb),
                "fps": asset.clips[other].fps,
                "frame": f_glb,
                "action": other,
                "out": str(tmp_path / f"{asset.name}.glb.npy"),
            }
        )
        expect.append((asset, other, f_glb))
    out = run_blender(BLENDER_CHECK, json.dumps(jobs))
    results = json.loads(out.split("RESULT", 1)[1].splitlines()[0])
    for job, res, (asset, clip, frame) in zip(jobs, results, expect, strict=True):
        what = f"{asset.name} {job['kind']}"
        # USD: a bone per joint; glTF: a bone per skin joint (unweighted roots stay plain nodes).
        bones = asset.num_joints if job["kind"] == "usd" else len(read_skin_joints(job["path"]))
        assert res["armatures"] == 1 and res["bones"] == [bones], what
        assert res["skinned"] >= 1, what
        T = asset.clips[clip].num_frames
        if job["kind"] == "usd":  # Blender makes one action: the bound clip, time codes 0..T-1
            assert len(res["actions"]) == 1, what
            (rng,) = res["actions"].values()
        else:  # one action per clip, named after it
            assert len(res["actions"]) == len(asset.clips), what
            rng = min(
                ((n, r) for n, r in res["actions"].items() if n == clip or n.startswith(clip + "_")),
                key=lambda x: len(x[0]),
            )[1]
        assert rng == pytest.approx([0.0, T - 1], abs=1e-3), what
        theirs = np.load(job["out"])
        ours = to_blender(asset.pose(clip, frame))
        assert len(theirs) == len(ours), what
        assert set_distance(theirs, ours) <= TOL * asset.size(), what


@pytest.fixture(scope="module")
def blender_written(tmp_path_factory):
    """FBX, COLLADA and BVH files that Blender writes from a starter animal."""
    if bpy_problem() is not None:
        pytest.skip(f"Blender's bpy module is not importable ({bpy_problem()})")
    d = tmp_path_factory.mktemp("blender_out")
    asset = build_animal("quadruped")
    glb = save_glb(asset, d / "quadruped.glb", clips=["walk"])
    run_blender(BLENDER_WRITE, str(glb), str(d / "quadruped"))
    return asset, d


def _needs_assimp():
    from zooctl.io.assimp import assimp_command

    if assimp_command() is None:
        pytest.skip("the assimp command is not installed (Debian package assimp-utils)")


def _shape(points: np.ndarray) -> np.ndarray:
    """Points centred and scaled to a unit bounding-box diagonal (FBX writes centimetres)."""
    lo, hi = points.min(0), points.max(0)
    return (points - 0.5 * (lo + hi)) / np.linalg.norm(hi - lo)


@pytest.mark.parametrize("suffix", [".fbx", ".dae"])
def test_assimp_imports_what_blender_writes(blender_written, suffix):
    from zooctl.io.assimp import load_with_assimp

    _needs_assimp()
    asset, d = blender_written
    got = load_with_assimp(d / f"quadruped{suffix}", "converted")
    assert got.meta["converted_by"] == "assimp"
    # COLLADA prefixes bone names with the armature's name.
    assert all(any(g == n or g.endswith("_" + n) for g in got.joint_names) for n in asset.joint_names)
    assert got.clips, "the walk animation was lost"
    clip = next(iter(got.clips.values()))
    assert clip.num_frames >= asset.clips["walk"].num_frames
    # Same bind-pose surface, whatever the file's unit and up axis (exporters differ on which
    # scene frame a clip starts at and on FBX node pivots; the bound mesh is unambiguous), and the
    # clip moves it.
    ours = _shape(asset.vertices.astype(np.float64))
    theirs = got.vertices.astype(np.float64)
    candidates = [_shape(theirs), _shape(np.stack([theirs[:, 0], theirs[:, 2], -theirs[:, 1]], 1))]
    assert min(set_distance(c, ours) for c in candidates) <= 2e-3
    moved = np.abs(got.pose(clip.name, 8) - got.pose(clip.name, 0)).max()
    assert moved > 0.01 * got.size()


def test_assimp_bvh_motion(tmp_path):
    """A hand-written BVH: assimp gives bones a pyramid mesh; the motion moves it as written."""
    from zooctl.io.assimp import load_with_assimp

    _needs_assimp()
    bvh = tmp_path / "walk.bvh"
    bvh.write_text(
        textwrap.dedent("""\
        HIERARCHY
        ROOT Hips
        {
          OFFSET 0.0 0.0 0.0
          CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
          JOINT Spine
          {
            OFFSET 0.0 10.0 0.0
            CHANNELS 3 Zrotation Xrotation Yrotation
            End Site
            {
              OFFSET 0.0 10.0 0.0
            }
          }
        }
        MOTION
        Frames: 3
        Frame Time: 0.03333334
        0 0 0 0 0 0 0 0 0
        0 1 0 0 0 0 0 0 0
        0 2 0 0 0 0 0 0 90
        """)
    )
    asset = load_with_assimp(bvh, "walk")
    assert {"Hips", "Spine"} <= set(asset.joint_names)
    (clip,) = asset.clips.values()
    assert clip.num_frames == 3 and clip.fps == 30.0
    p0, p1 = asset.pose(clip.name, 0), asset.pose(clip.name, 1)
    np.testing.assert_allclose(p1 - p0, np.tile([0.0, 1.0, 0.0], (len(p0), 1)), atol=1e-4)  # the root rises 1
    # Frame 2 turns the spine 90 degrees about Y: its vertices keep their height, not their place.
    p2 = asset.pose(clip.name, 2)
    moved = np.linalg.norm(p2 - p0 - [0.0, 2.0, 0.0], axis=1) > 1e-3
    assert moved.any() and not moved.all()
    np.testing.assert_allclose(p2[:, 1] - p0[:, 1], 2.0, atol=1e-4)


def test_missing_assimp_says_how_to_install(tmp_path, monkeypatch):
    from zooctl.errors import MissingDependencyError
    from zooctl.io.assimp import load_with_assimp

    f = tmp_path / "x.fbx"
    f.write_bytes(b"Kaydara FBX Binary  \x00")
    monkeypatch.setenv("ZOOCTL_ASSIMP", str(tmp_path / "no-such-assimp"))
    with pytest.raises(MissingDependencyError) as info:
        load_with_assimp(f, "x")
    assert "assimp-utils" in info.value.hint


def test_broken_fbx_is_a_clear_error(tmp_path):
    from zooctl.errors import InputError
    from zooctl.io.assimp import load_with_assimp

    _needs_assimp()
    f = tmp_path / "broken.fbx"
    f.write_bytes(b"Kaydara FBX Binary  \x00" + b"\x01" * 64)
    with pytest.raises(InputError, match="broken.fbx: assimp could not convert it"):
        load_with_assimp(f, "x")
