"""The fit's colour bake (`zooctl.fit.texture`): a procedural animal rendered unlit with known
colours through a known camera is baked back, and the colours must come back where it was seen,
from its mirror side where it was not; the baked character exports as a valid GLB (Khronos
glTF-Validator) and USD (UsdValidation) and Blender shows its colours; `zooctl fit` bakes by
default and `--no-texture` keeps the template's colours."""

from __future__ import annotations

import dataclasses
import io
import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import torch

from zooctl.asset import Clip, RiggedAsset
from zooctl.fit.texture import bake, linear_to_srgb, srgb_to_linear, uv_samples
from zooctl.procedural import build_animal
from zooctl.render.camera import look_at
from zooctl.render.raster import interpolate, rasterize

T, H, W = 6, 240, 320
BACKGROUND = (30, 160, 40)


def animal() -> RiggedAsset:
    """The procedural quadruped with a 6-frame ``fit`` clip taken from its walk."""
    a = build_animal("quadruped", name="quad")
    c = a.clips["walk"]
    idx = np.linspace(0, c.num_frames - 1, T).astype(int)
    clip = Clip("fit", 30.0, c.rotations[idx], c.translations[idx], c.scales[idx])
    return dataclasses.replace(a, clips={"fit": clip})


def side_camera(asset: RiggedAsset):
    """A camera seeing the animal from one side (and a little above): its other side is hidden."""
    rest = asset.pose()
    centre = 0.5 * (rest.max(0) + rest.min(0))
    lo, hi = rest.min(0), rest.max(0)
    side = int(np.argmin(hi - lo))  # the thinnest axis is left-right for a quadruped
    offset = np.zeros(3)
    offset[side] = 1.6
    offset[1] = 0.5
    return look_at(centre + np.linalg.norm(hi - lo) * offset, centre, H, W, 40.0)


def render_unlit(asset: RiggedAsset, camera, albedo: np.ndarray):
    """(frames uint8 sRGB, masks, face ids) of the ``fit`` clip with per-vertex linear ``albedo``,
    no shading, over a green background."""
    posed = torch.as_tensor(asset.pose("fit", np.arange(T)).astype(np.float32))
    faces = torch.as_tensor(asset.faces, dtype=torch.long)
    frags = rasterize(posed, faces, camera.expand(T))
    col = interpolate(torch.as_tensor(albedo)[None].expand(T, -1, -1).contiguous(), faces, frags).numpy()
    frames = (linear_to_srgb(col) * 255 + 0.5).astype(np.uint8)
    masks = frags.mask.numpy()
    frames[~masks] = BACKGROUND
    return frames, masks, frags.face_ids.numpy()


def uniform_vertices(asset: RiggedAsset, colours: np.ndarray, tol: float = 0.02) -> np.ndarray:
    """(V,) bool: vertices whose faces all have their colour (within ``tol``), where the truth is
    the same at the scale of a pixel (a face here is a pixel or two)."""
    tri = colours[asset.faces]  # (F, 3, 3)
    spread = np.abs(tri - tri.mean(1, keepdims=True)).max(axis=(1, 2))
    worst = np.zeros(asset.num_vertices)
    for k in range(3):
        np.maximum.at(worst, asset.faces[:, k], spread)
    return worst < tol


def seen_faces(face_ids: np.ndarray, num_faces: int) -> np.ndarray:
    seen = np.zeros(num_faces, bool)
    seen[np.unique(face_ids[face_ids >= 0])] = True
    return seen


def per_face_atlas(asset: RiggedAsset) -> RiggedAsset:
    """``asset`` with one vertex per face corner and non-overlapping UVs: each face its own
    triangle in a grid of cells (grey vertex colours, a placeholder texture)."""
    F = asset.num_faces
    n = int(np.ceil(np.sqrt(F / 2)))
    cell = 1.0 / n
    k = np.arange(F)
    lo = np.stack([(k // 2) % n, (k // 2) // n], 1) * cell + 0.1 * cell
    hi = lo + 0.8 * cell
    a, b = np.stack([hi[:, 0], lo[:, 1]], 1), np.stack([lo[:, 0], hi[:, 1]], 1)
    uv = np.where((k % 2 == 0)[:, None, None], np.stack([lo, a, b], 1), np.stack([hi, b, a], 1))
    vid = asset.faces.reshape(-1)
    return dataclasses.replace(
        asset,
        vertices=asset.vertices[vid],
        faces=np.arange(3 * F, dtype=np.int32).reshape(F, 3),
        skin_joints=asset.skin_joints[vid],
        skin_weights=asset.skin_weights[vid],
        vertex_colors=None,
        uvs=uv.reshape(-1, 2).astype(np.float32),
        texture_png=_png(np.full((4, 4, 3), 128, np.uint8)),
    ).validate()


def _png(rgb: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(rgb).save(buf, format="PNG")
    return buf.getvalue()


@pytest.fixture(scope="module")
def scene():
    a = animal()
    truth = a.vertex_colors.copy()
    cam = side_camera(a)
    frames, masks, fids = render_unlit(a, cam, truth)
    return a, truth, cam, frames, masks, fids


@pytest.fixture(scope="module")
def vertex_bake(scene):
    a, truth, cam, frames, masks, _ = scene
    grey = dataclasses.replace(a, vertex_colors=np.full_like(truth, 0.5))
    return bake(grey, cam, frames, masks, make_uvs=False)


def test_vertex_colours_come_back_where_seen(scene, vertex_bake):
    a, truth, _, _, _, fids = scene
    out, info = vertex_bake
    assert info["mode"] == "vertex" and out.texture_png is None
    seen = np.zeros(a.num_vertices, bool)
    seen[a.faces[seen_faces(fids, a.num_faces)].reshape(-1)] = True
    assert 0.3 < seen.mean() < 0.8  # one side seen, the other not
    err = np.abs(out.vertex_colors - truth).max(1)
    grey = np.abs(0.5 - truth).max(1)
    assert np.median(err[seen]) < 0.03, np.median(err[seen])
    assert np.median(err[seen]) < 0.2 * np.median(grey[seen])  # not the colours it started with
    flat = seen & uniform_vertices(a, truth)
    assert flat.sum() > 0.5 * seen.sum()
    assert np.quantile(err[flat], 0.75) < 0.05, np.quantile(err[flat], 0.75)


def test_the_hidden_side_takes_its_mirror_images_colours(scene, vertex_bake):
    a, truth, _, _, _, fids = scene
    out, info = vertex_bake
    seen = np.zeros(a.num_vertices, bool)
    seen[a.faces[seen_faces(fids, a.num_faces)].reshape(-1)] = True
    assert info["mirrored"] > 0.2
    err = np.abs(out.vertex_colors - truth).max(1)
    grey = np.abs(0.5 - truth).max(1)
    # The procedural animal's colours are left/right symmetric: the hidden side comes out close.
    assert np.median(err[~seen]) < 0.06, np.median(err[~seen])
    assert np.median(err[~seen]) < 0.35 * np.median(grey[~seen])


def test_only_surface_in_front_gets_weight(scene):
    """The z-buffer decides: face corners that no frame shows (even at 4x the resolution, where
    faces are not sub-pixel) get almost none of the weight, those shown nearly all get some."""
    from zooctl.fit.texture import corner_samples, observe

    a, _, cam, frames, masks, _ = scene
    samples = corner_samples(a.faces)
    _, w = observe(a, cam, frames, masks, samples)
    k = 4
    fine = dataclasses.replace(cam, intrinsics=cam.intrinsics * k, height=H * k, width=W * k)
    posed = torch.as_tensor(a.pose("fit", np.arange(T)).astype(np.float32))
    fids = rasterize(posed, torch.as_tensor(a.faces, dtype=torch.long), fine.expand(T)).face_ids.numpy()
    shown = seen_faces(fids, a.num_faces)[samples.face]
    assert w[~shown].sum() < 0.04 * w.sum(), w[~shown].sum() / w.sum()
    assert (w[shown] > 0).mean() > 0.9


def test_symmetry_is_judged_on_the_reference_shape(scene):
    """A fit bends the template (displacements, stretched bones): the mirror side is found on the
    template's shape, which has the character's vertices, not on the bent one."""
    a, truth, cam, _, _, _ = scene
    v = a.vertices.astype(np.float64)
    side, length = int(np.argmin(np.ptp(v, 0))), int(np.argmax(np.ptp(v, 0)))
    centre = 0.5 * (v[:, side].max() + v[:, side].min())
    v[v[:, side] > centre, length] += 0.1 * np.ptp(v[:, length])  # one side moved forward
    bent = dataclasses.replace(a, vertices=v.astype(np.float32))
    frames, masks, _ = render_unlit(bent, cam, truth)
    _, own = bake(bent, cam, frames, masks, make_uvs=False)
    out, ref = bake(bent, cam, frames, masks, reference=a.vertices, make_uvs=False)
    assert own["mirrored"] == 0 and ref["mirrored"] > 0.2
    from zooctl.errors import InputError

    with pytest.raises(InputError, match="reference shape"):
        bake(bent, cam, frames, masks, reference=a.vertices[:-1])


def test_a_uv_texture_is_baked_where_the_uvs_allow(scene):
    a, truth, cam, frames, masks, fids = scene
    atlas = per_face_atlas(a)
    out, info = bake(atlas, cam, frames, masks, texture_size=256)
    assert info["mode"] == "texture" and info["texture_size"] == 256
    assert out.vertex_colors is None and out.texture_png is not None and out.uvs is not None
    from PIL import Image

    img = np.asarray(Image.open(io.BytesIO(out.texture_png)).convert("RGB"))
    assert img.shape == (256, 256, 3)
    smp = uv_samples(atlas.uvs, atlas.faces, 256)
    want = np.einsum("sk,skc->sc", smp.bary, truth[a.faces[smp.face]])
    got = srgb_to_linear(img.reshape(-1, 3)[smp.texel] / 255.0)
    err = np.abs(got - want).max(1)
    vis = seen_faces(fids, a.num_faces)[smp.face]
    assert np.median(err[vis]) < 0.03, np.median(err[vis])
    assert np.median(err[~vis]) < 0.08, np.median(err[~vis])


def test_overlapping_or_stray_uvs_bake_vertex_colours(scene):
    a, _, cam, frames, masks, _ = scene
    stacked = dataclasses.replace(a, uvs=np.tile([[0.2, 0.3]], (a.num_vertices, 1)).astype(np.float32))
    assert uv_samples(stacked.uvs, a.faces) is None
    rng = np.random.default_rng(0)
    assert uv_samples(rng.random((a.num_vertices, 2)).astype(np.float32), a.faces) is None  # overlapping
    assert uv_samples(rng.random((a.num_vertices, 2)).astype(np.float32) + 1.5, a.faces) is None
    out, info = bake(stacked, cam, frames[:2], masks[:2], make_uvs=False)
    assert info["mode"] == "vertex" and out.vertex_colors is not None and out.texture_png is None
    out, info = bake(stacked, cam, frames[:2], masks[:2], texture_size=128)  # an atlas replaces them
    assert info["mode"] == "texture" and info["uvs"] == "generated" and out.texture_png is not None


def test_a_character_no_frame_sees_keeps_its_colours(scene):
    a, _, cam, frames, masks, _ = scene
    out, info = bake(a, cam, frames, np.zeros_like(masks))
    assert info["mode"] == "none" and out is a


def test_pixels_outside_the_mask_give_no_colour(scene):
    """The background is green; a mask that leaves the animal's border out must keep green off it."""
    a, truth, cam, frames, masks, fids = scene
    grey = dataclasses.replace(a, vertex_colors=np.full_like(truth, 0.5))
    out, _ = bake(grey, cam, frames, masks, make_uvs=False)
    bg = srgb_to_linear(np.array(BACKGROUND) / 255.0)
    seen = np.zeros(a.num_vertices, bool)
    seen[a.faces[seen_faces(fids, a.num_faces)].reshape(-1)] = True
    greenish = np.abs(out.vertex_colors - bg).max(1) < 0.05
    assert greenish[seen].mean() < 0.01


# -- export ---------------------------------------------------------------------------------------


def _validator() -> str | None:
    """The global npm package's folder of the Khronos glTF-Validator, or None."""
    if shutil.which("node") is None or shutil.which("npm") is None:
        return None
    root = subprocess.run(["npm", "root", "-g"], capture_output=True, text=True, timeout=60).stdout.strip()
    return root if root and (Path(root) / "gltf-validator").is_dir() else None


VALIDATE_JS = textwrap.dedent("""
    const fs = require('fs');
    const v = require('gltf-validator');
    v.validateBytes(new Uint8Array(fs.readFileSync(process.argv[1])))
      .then(r => console.log(JSON.stringify(r.issues)))
      .catch(e => { console.error(e); process.exit(2); });
""")


@pytest.fixture(scope="module")
def baked_assets(scene, vertex_bake):
    a, _, cam, frames, masks, _ = scene
    textured, _ = bake(per_face_atlas(a), cam, frames, masks, texture_size=128)
    atlas, info = bake(a, cam, frames, masks, texture_size=128)
    assert info["uvs"] == "generated"
    return {"vertex": vertex_bake[0], "texture": textured, "atlas": atlas}


@pytest.mark.skipif(
    _validator() is None,
    reason="the Khronos glTF-Validator is not installed (`npm install -g gltf-validator`; .ci/run does it)",
)
@pytest.mark.parametrize("kind", ["vertex", "texture", "atlas"])
def test_glb_passes_the_khronos_validator(baked_assets, kind, tmp_path):
    from zooctl.io.gltf_export import save_glb

    path = save_glb(baked_assets[kind], tmp_path / f"{kind}.glb")
    p = subprocess.run(
        ["node", "-e", VALIDATE_JS, str(path)],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "NODE_PATH": _validator()},
    )
    assert p.returncode == 0, p.stderr
    issues = json.loads(p.stdout)
    assert issues["numErrors"] == 0, [m for m in issues["messages"] if m["severity"] == 0]


@pytest.mark.parametrize("kind", ["vertex", "texture", "atlas"])
def test_glb_and_usd_carry_the_colours(baked_assets, kind, tmp_path):
    from pxr import Usd, UsdGeom, UsdShade, UsdValidation

    from zooctl.io.gltf_export import gltf_document
    from zooctl.io.usd_export import save_usd

    asset = baked_assets[kind]
    doc, _ = gltf_document(asset, ["fit"])
    prim = doc["meshes"][0]["primitives"][0]
    pbr = doc["materials"][0]["pbrMetallicRoughness"]
    if kind == "vertex":
        assert "COLOR_0" in prim["attributes"] and "baseColorTexture" not in pbr
    else:
        assert "TEXCOORD_0" in prim["attributes"] and "COLOR_0" not in prim["attributes"]
        assert pbr["baseColorTexture"]["index"] == 0 and doc["images"][0]["mimeType"] == "image/png"

    path = save_usd(asset, tmp_path / "baked.usda")
    stage = Usd.Stage.Open(str(path))
    reg = UsdValidation.ValidationRegistry()
    errors = UsdValidation.ValidationContext(reg.GetOrLoadAllValidators()).Validate(stage)
    assert not [e for e in errors if e.GetType() == UsdValidation.ValidationErrorType.Error]
    mesh = next(UsdGeom.Mesh(p) for p in stage.Traverse() if p.IsA(UsdGeom.Mesh))
    mat, _ = UsdShade.MaterialBindingAPI(mesh.GetPrim()).ComputeBoundMaterial()
    diffuse = UsdShade.Shader(stage.GetPrimAtPath(mat.GetPath().AppendChild("PreviewSurface")))
    source = diffuse.GetInput("diffuseColor").GetConnectedSources()[0][0].source
    if kind == "vertex":
        col = np.array(mesh.GetDisplayColorPrimvar().Get())
        assert np.allclose(col, asset.vertex_colors, atol=1e-6)
        # A renderer that shows materials only still shows the vertex colours.
        reader = UsdShade.Shader(source.GetPrim())
        assert reader.GetIdAttr().Get() == "UsdPrimvarReader_float3"
        assert reader.GetInput("varname").Get() == "displayColor"
    else:
        assert UsdShade.Shader(source.GetPrim()).GetIdAttr().Get() == "UsdUVTexture"
        shader = UsdShade.Shader(stage.GetPrimAtPath(mat.GetPath().AppendChild("BaseColor")))
        tex = shader.GetInput("file").Get().path
        assert (tmp_path / tex).read_bytes() == asset.texture_png


def test_the_stored_character_keeps_its_baked_colours(baked_assets, tmp_path):
    from zooctl.store.fits import FitStore

    fits = FitStore(tmp_path)
    fits.save_record("f", {"status": "done"})
    for kind, asset in baked_assets.items():
        fits.save_character("f", asset)
        back = fits.character("f")
        if kind == "vertex":
            assert np.array_equal(back.vertex_colors, asset.vertex_colors) and back.texture_png is None
        else:
            assert back.texture_png == asset.texture_png and np.array_equal(back.uvs, asset.uvs)


BLENDER_JS = textwrap.dedent("""
    import json, sys
    import bpy
    bpy.ops.wm.read_factory_settings(use_empty=True)
    if sys.argv[-1].endswith(".glb"):
        bpy.ops.import_scene.gltf(filepath=sys.argv[-1])
    else:
        bpy.ops.wm.usd_import(filepath=sys.argv[-1])
    out = {"images": [], "attributes": [], "nodes": []}
    for o in bpy.data.objects:
        if o.type != "MESH":
            continue
        out["attributes"] += [a.name for a in o.data.color_attributes]
        for slot in o.material_slots:
            tree = slot.material.node_tree
            bsdf = next(n for n in tree.nodes if n.type == "BSDF_PRINCIPLED")
            link = bsdf.inputs["Base Color"].links
            seen, todo = [], [l.from_node for l in link]
            while todo:  # every node feeding the base colour
                n = todo.pop()
                seen.append(n.type)
                if n.type == "TEX_IMAGE" and n.image is not None:
                    out["images"].append(list(n.image.size))
                todo += [l.from_node for i in n.inputs for l in i.links]
            out["nodes"] += seen
    print("RESULT " + json.dumps(out))
""")


def _bpy_missing() -> str | None:
    p = subprocess.run([sys.executable, "-c", "import bpy"], capture_output=True, text=True, timeout=300)
    return None if p.returncode == 0 else (p.stderr.strip().splitlines() or ["import failed"])[-1]


@pytest.mark.parametrize("fmt", ["glb", "usd"])
@pytest.mark.parametrize("kind", ["vertex", "texture", "atlas"])
def test_blender_shows_the_colours(baked_assets, kind, fmt, tmp_path):
    """Blender's glTF and USD importers: a texture feeds the material's base colour in both; vertex
    colours do from the GLB. From the USD they come in as the ``displayColor`` colour attribute
    (Blender 4.2's importer does not follow the material's UsdPrimvarReader_float3, which other
    USD readers do; the baked fit exports a texture, so this is only --no-texture's case)."""
    why = _bpy_missing()
    if why is not None:
        pytest.skip(f"Blender's bpy module is not importable ({why}); `make install` installs bpy==4.2.0")
    from zooctl.io.gltf_export import save_glb
    from zooctl.io.usd_export import save_usd

    save = save_glb if fmt == "glb" else save_usd
    path = save(baked_assets[kind], tmp_path / f"{kind}.{fmt}")
    script = tmp_path / "check.py"
    script.write_text(BLENDER_JS)
    p = subprocess.run([sys.executable, str(script), str(path)], capture_output=True, text=True, timeout=600)
    line = [s for s in p.stdout.splitlines() if s.startswith("RESULT ")]
    assert line, p.stdout[-2000:] + p.stderr[-2000:]
    out = json.loads(line[-1][len("RESULT ") :])
    if kind != "vertex":
        assert out["images"] == [[128, 128]], out
    elif fmt == "glb":
        assert out["attributes"] and "VERTEX_COLOR" in out["nodes"], out
    else:
        assert out["attributes"] == ["displayColor"], out


# -- zooctl fit ------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def small_video(tmp_path_factory):
    from fit_helpers import small_quadruped_video

    return small_quadruped_video(tmp_path_factory.mktemp("texfit"))


def _fit(store: Path, folder: Path, cfg: Path, name: str, *extra: str) -> dict:
    from cli_helpers import run_in_store

    code = run_in_store(
        store,
        "fit",
        str(folder),
        *("--template", "quadruped", "--config", str(cfg), "--name", name),
        *("--out", str(store.parent / name), "--json", *extra),
    )
    assert code == 0
    return json.loads((store / "fits" / name / "record.json").read_text())


def test_fit_bakes_by_default_and_no_texture_keeps_the_templates_colours(small_video, tmp_path):
    from fit_helpers import tiny_overrides

    from zooctl.io.gltf_import import load_gltf
    from zooctl.store.bank import Bank
    from zooctl.store.fits import FitStore

    store, folder, _ = small_video
    cfg = tmp_path / "tiny.json"
    cfg.write_text(json.dumps(tiny_overrides()))
    template = Bank(store).get("quadruped")
    fits = FitStore(store)

    rec = _fit(store, folder, cfg, "baked")
    # The template has no UVs: the character gets an atlas and wears a texture.
    assert rec["texture"]["mode"] == "texture" and rec["texture"]["uvs"] == "generated"
    assert rec["timings"]["texture"] > 0
    baked = fits.character("baked")
    assert baked.texture_png is not None and baked.vertex_colors is None and baked.uvs is not None
    glb = load_gltf(rec["outputs"]["glb"], "baked")  # what the user gets wears the baked colours
    assert glb.texture_png == baked.texture_png and np.allclose(glb.uvs, baked.uvs, atol=1e-6)
    usd = Path(rec["outputs"]["usd"])
    assert (usd.parent / f"{usd.stem}.texture.png").read_bytes() == baked.texture_png

    rec = _fit(store, folder, cfg, "plain", "--no-texture")
    assert rec["texture"] is None and "texture" not in rec["timings"] and rec["config"]["texture"] is False
    plain = fits.character("plain")
    assert np.array_equal(plain.vertex_colors, template.vertex_colors)


def test_uvs_without_a_texture_survive_import(scene, tmp_path):
    """A template with UVs but no texture keeps its UVs through glTF, so a fit can bake into them."""
    from zooctl.io.gltf_export import save_glb
    from zooctl.io.gltf_import import load_gltf

    atlas = dataclasses.replace(per_face_atlas(scene[0]), texture_png=None)
    back = load_gltf(save_glb(atlas, tmp_path / "uv.glb"), "uv")
    assert back.texture_png is None and back.uvs is not None
    assert np.allclose(back.uvs, atlas.uvs, atol=1e-6)
    assert uv_samples(back.uvs, back.faces, 64) is not None


# -- generated UVs ---------------------------------------------------------------------------------


def render_pattern(asset: RiggedAsset, camera, period: float):
    """(frames uint8 sRGB, masks): the ``fit`` clip wearing stripes of ``period`` (a fraction of
    the animal's length) laid on its rest shape, finer than its faces, unlit over green."""
    posed = torch.as_tensor(asset.pose("fit", np.arange(T)).astype(np.float32))
    faces = torch.as_tensor(asset.faces, dtype=torch.long)
    frags = rasterize(posed, faces, camera.expand(T))
    rest = torch.as_tensor(asset.vertices.astype(np.float32))[None].expand(T, -1, -1).contiguous()
    p = interpolate(rest, faces, frags).numpy()
    length = float(np.ptp(asset.vertices, 0).max())
    phase = 2 * np.pi * p / (period * length)
    col = 0.45 + 0.35 * np.sin(phase[..., [0, 1, 2]] + phase[..., [1, 2, 0]])
    frames = (linear_to_srgb(col) * 255 + 0.5).astype(np.uint8)
    masks = frags.mask.numpy()
    frames[~masks] = BACKGROUND
    return frames, masks


def rendered_psnr(asset: RiggedAsset, camera, frames: np.ndarray, masks: np.ndarray) -> float:
    """PSNR (dB, sRGB) of ``asset``'s colours rendered unlit through ``camera`` inside ``masks``."""
    from zooctl.render.albedo import decode_texture, render_colours

    posed = asset.pose("fit", np.arange(T))
    tex = None if asset.texture_png is None else decode_texture(asset.texture_png)
    rgb, cover = render_colours(posed, asset.faces, camera, asset.vertex_colors, asset.uvs, tex)
    m = masks & cover
    got = linear_to_srgb(rgb[m]) * 255
    mse = float(np.mean((got - frames[m].astype(np.float64)) ** 2))
    return 10 * np.log10(255.0**2 / max(mse, 1e-9))


def test_a_character_without_uvs_gets_an_atlas_and_a_texture(scene):
    a, truth, cam, frames, masks, fids = scene
    assert a.uvs is None
    grey = dataclasses.replace(a, vertex_colors=np.full_like(truth, 0.5))
    out, info = bake(grey, cam, frames, masks, texture_size=256)
    assert info["mode"] == "texture" and info["uvs"] == "generated"
    assert out.vertex_colors is None and out.texture_png is not None
    # The same surface and skinning: faces in the same order, seam vertices split.
    assert out.num_faces == a.num_faces and a.num_vertices <= out.num_vertices < 1.6 * a.num_vertices
    assert np.allclose(out.vertices[out.faces], a.vertices[a.faces])
    assert np.allclose(out.pose("fit", [3])[0][out.faces], a.pose("fit", [3])[0][a.faces], atol=1e-5)
    assert uv_samples(out.uvs, out.faces, 256) is not None  # in the unit square, not overlapping
    # Rendered back through the camera it was baked from, it looks like the frames.
    assert rendered_psnr(out, cam, frames, masks) > 30


def test_a_texture_holds_detail_that_vertex_colours_lose(scene):
    """Stripes finer than the faces: a texture in generated UVs keeps them, vertex colours blur
    them; judged by rendering each back through the camera that saw them."""
    a, _, cam, _, _, _ = scene
    frames, masks = render_pattern(a, cam, 0.08)
    tex, info = bake(a, cam, frames, masks)
    vert, _ = bake(a, cam, frames, masks, make_uvs=False)
    assert info["mode"] == "texture"
    p_tex, p_vert = rendered_psnr(tex, cam, frames, masks), rendered_psnr(vert, cam, frames, masks)
    assert p_tex > p_vert + 3, (p_tex, p_vert)


def test_resume_follows_no_texture(small_video, tmp_path):
    """A fit interrupted in stage 2 and resumed with --no-texture keeps the template's colours
    (the resumed fit took its whole config from the saved state, --no-texture included)."""
    from cli_helpers import run_in_store
    from fit_helpers import tiny_fit_config

    from zooctl.fit.job import fit_job
    from zooctl.store.bank import Bank
    from zooctl.store.fits import FitStore

    store, folder, _ = small_video
    cfg = tiny_fit_config(4)
    cfg.checkpoint_every = 1

    class StopInStage2:
        name = ""

        def stage(self, name, total, done=0):
            self.name = name

        def step(self, terms):
            if self.name == "stage2":
                raise KeyboardInterrupt

        def message(self, text):
            pass

    with pytest.raises(KeyboardInterrupt):
        fit_job(str(folder), store, cfg, name="paused", template="quadruped", reporter=StopInStage2())
    fits = FitStore(store)
    assert fits.get("paused")["status"] == "interrupted" and fits.load_state("paused")["config"]["texture"]
    code = run_in_store(store, "fit", str(folder), "--name", "paused", "--resume", "--no-texture", "--json")
    assert code == 0
    rec = fits.get("paused")
    assert rec["status"] == "done" and rec["texture"] is None and rec["config"]["texture"] is False
    plain = fits.character("paused")
    assert plain.texture_png is None
    assert np.array_equal(plain.vertex_colors, Bank(store).get("quadruped").vertex_colors)
