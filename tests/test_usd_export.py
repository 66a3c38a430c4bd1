"""USD export checked by usd-core itself: UsdValidation, UsdSkel's own skinning, and the round trip
through our UsdSkel importer, on the 28 shared assets and every starter animal."""

from __future__ import annotations

import functools
import io

import numpy as np
import pytest
from conftest import needs_shared_assets, shared_assets

from zooctl.errors import InputError, UsageError
from zooctl.io.rig_compare import posed_difference, posed_error_bound
from zooctl.io.usd_export import save_usd
from zooctl.io.usd_import import load_usd
from zooctl.procedural import build_animal, starter_assets

pxr = pytest.importorskip("pxr", reason="usd-core is not installed")
from pxr import Usd, UsdGeom, UsdSkel, UsdValidation, Vt  # noqa: E402

TOL = 1e-4  # of the model's size, as the issue asks


@functools.cache
def _validators():
    return UsdValidation.ValidationRegistry().GetOrLoadAllValidators()


def validation_errors(path) -> list[str]:
    """Every error (not warning) that all registered usd-core validators report on the file."""
    stage = Usd.Stage.Open(str(path))
    errors = UsdValidation.ValidationContext(_validators()).Validate(stage)
    return [
        f"{e.GetValidator().GetMetadata().name if e.GetValidator() else '?'}: {e.GetMessage()}"
        for e in errors
        if e.GetType() == UsdValidation.ValidationErrorType.Error
    ]


def usdskel_posed(stage, frame_times: list[float]) -> list[np.ndarray]:
    """Skin the exported mesh with UsdSkel's own code (UsdSkel.Cache, SkinningQuery) at time codes."""
    root = UsdSkel.Root(stage.GetDefaultPrim())
    cache = UsdSkel.Cache()
    cache.Populate(root, Usd.PrimDefaultPredicate)
    (binding,) = cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate)
    skel_query = cache.GetSkelQuery(binding.GetSkeleton())
    (skinning,) = binding.GetSkinningTargets()
    mesh = UsdGeom.Mesh(skinning.GetPrim())
    out = []
    for t in frame_times:
        points = Vt.Vec3fArray(mesh.GetPointsAttr().Get(t))
        assert skinning.ComputeSkinnedPoints(skel_query.ComputeSkinningTransforms(t), points, t)
        out.append(np.array(points, dtype=np.float64))
    return out


def select_animation(path, variant: str):
    """Open the file with the "animation" variant set to one clip (the way a user picks a clip)."""
    stage = Usd.Stage.Open(str(path))
    stage.GetDefaultPrim().GetVariantSet("animation").SetVariantSelection(variant)
    return stage


def check_export(asset, path) -> None:
    """The full check of one export: validators, UsdSkel skinning, round trip."""
    save_usd(asset, path)
    assert validation_errors(path) == []
    size = asset.size()
    # UsdSkel's skinning of the bound (first) clip at several frames.
    first = next(iter(asset.clips))
    T = asset.clips[first].num_frames
    frames = sorted({0, T // 3, T - 1})
    ours = asset.pose(first, np.array(frames))
    for k, got in enumerate(usdskel_posed(Usd.Stage.Open(str(path)), [float(f) for f in frames])):
        assert np.abs(got - ours[k]).max() <= TOL * size, f"{first} frame {frames[k]}"
    # Round trip: every frame of every clip (bound), sampled frames literally.
    back = load_usd(path, "back")
    assert list(back.clips) == list(asset.clips)
    for name, clip in asset.clips.items():
        assert back.clips[name].num_frames == clip.num_frames and back.clips[name].fps == clip.fps
        fr = sorted({0, clip.num_frames // 2, clip.num_frames - 1})
        assert posed_difference(asset, back, name, fr) <= TOL * size, name
    assert posed_error_bound(asset, back) <= TOL * size
    assert back.joint_names == asset.joint_names
    np.testing.assert_array_equal(back.faces, asset.faces)


@needs_shared_assets
@pytest.mark.parametrize("path", shared_assets(), ids=lambda p: p.stem)
def test_shared_asset_usd_export(path, tmp_path):
    from zooctl.io.gltf_import import load_gltf

    asset = load_gltf(path, path.stem)
    check_export(asset, tmp_path / f"{path.stem}.usdc")


@pytest.mark.parametrize("asset", starter_assets(0), ids=lambda a: a.name)
def test_starter_animal_usd_export(asset, tmp_path):
    check_export(asset, tmp_path / f"{asset.name}.usd")


def test_usdskel_skins_other_clips_through_the_variant_set(tmp_path):
    asset = build_animal("bird")
    path = tmp_path / "bird.usda"
    save_usd(asset, path)
    for clip in asset.clips:
        f = asset.clips[clip].num_frames - 2
        (pts,) = usdskel_posed(select_animation(path, clip), [float(f)])
        assert np.abs(pts - asset.pose(clip, f)).max() <= TOL * asset.size(), clip


@pytest.mark.parametrize("suffix", [".usda", ".usdc", ".usd", ".usdz"])
def test_every_container_validates_and_round_trips(suffix, tmp_path):
    asset = build_animal("spider")
    path = tmp_path / f"spider{suffix}"
    save_usd(asset, path, clips=["walk"])
    assert validation_errors(path) == []
    head = path.read_bytes()[:8]
    if suffix == ".usda":
        assert head.startswith(b"#usda")
    elif suffix in (".usdc", ".usd"):
        assert head == b"PXR-USDC"
    else:
        assert head[:2] == b"PK"  # a zip package
    stage = Usd.Stage.Open(str(path))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetTimeCodesPerSecond() == 30.0
    assert stage.GetDefaultPrim().GetPath().pathString == "/spider"
    back = load_usd(path, "back")
    assert list(back.clips) == ["walk"]
    assert posed_error_bound(asset, back, ["walk"]) <= TOL * asset.size()


def test_camera_and_metadata(tmp_path):
    from zooctl.render.preview import fit_camera

    asset = build_animal("fish")
    asset.meta["meters_per_unit"] = 0.01
    cam = fit_camera(asset.vertices, 240, 320)
    path = tmp_path / "fish.usda"
    save_usd(asset, path, camera=cam)
    assert validation_errors(path) == []
    stage = Usd.Stage.Open(str(path))
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.01)
    usd_cam = UsdGeom.Camera(stage.GetPrimAtPath("/Camera"))
    assert usd_cam
    # The USD camera sees the model's centre where ours does: at the image centre.
    gf = usd_cam.GetCamera(Usd.TimeCode.Default())
    centre = np.mean(asset.bbox(), axis=0)
    to_cam = np.array(gf.transform.GetInverse()).T  # column-vector world -> camera (looks down -Z)
    p = to_cam @ np.r_[centre, 1.0]
    assert p[2] < 0 and abs(p[0] / p[2]) < 1e-3 and abs(p[1] / p[2]) < 1e-3
    assert load_usd(path, "back").meta["meters_per_unit"] == pytest.approx(0.01)


def test_texture_is_written_packaged_and_read_back(tmp_path):
    from PIL import Image

    asset = build_animal("snake")
    v = asset.vertices
    asset.uvs = np.stack(
        [(v[:, 2] - v[:, 2].min()) / np.ptp(v[:, 2]), (v[:, 1] - v[:, 1].min()) / np.ptp(v[:, 1])], 1
    ).astype(np.float32)
    img = np.zeros((16, 16, 3), np.uint8)
    img[::2] = (200, 40, 40)
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    asset.texture_png = buf.getvalue()
    for suffix in (".usdz", ".usda"):
        path = tmp_path / f"snake{suffix}"
        save_usd(asset, path)
        assert validation_errors(path) == []
        back = load_usd(path, "back")
        assert back.texture_png is not None
        np.testing.assert_array_equal(
            np.asarray(Image.open(io.BytesIO(back.texture_png)).convert("RGB")), img
        )
        np.testing.assert_allclose(back.uvs, asset.uvs, atol=1e-6)
    assert (tmp_path / "snake.texture.png").is_file()  # beside the .usda, referenced relatively


def test_names_that_are_not_usd_identifiers(tmp_path):
    asset = build_animal("insect", name="9-lives.v2")
    asset.joint_names = [f"mixamorig:{n}" if i % 2 else n for i, n in enumerate(asset.joint_names)]
    asset.joint_names[3] = "thorax 2"  # a space: invalid in USD, kept by zooctl
    path = tmp_path / "x.usda"
    save_usd(asset, path)
    assert validation_errors(path) == []
    back = load_usd(path, "back")
    assert back.joint_names == asset.joint_names  # the original names survive
    assert posed_error_bound(asset, back) <= TOL * asset.size()


def test_bad_requests_are_clear_errors(tmp_path):
    asset = build_animal("fish")
    with pytest.raises(UsageError, match="cannot write USD"):
        save_usd(asset, tmp_path / "x.obj")
    with pytest.raises(UsageError, match="no clip 'fly'"):
        save_usd(asset, tmp_path / "x.usda", clips=["fly"])
    assert not list(tmp_path.iterdir())  # nothing half-written
    bad = tmp_path / "bad.usda"
    bad.write_text("this is not usd")
    with pytest.raises(InputError, match="bad.usda"):
        load_usd(bad, "x")
    plain = tmp_path / "plain.usda"
    stage = Usd.Stage.CreateNew(str(plain))
    UsdGeom.Mesh.Define(stage, "/M")
    stage.Save()
    with pytest.raises(InputError, match="no UsdSkel skeleton"):
        load_usd(plain, "x")
    with pytest.raises(InputError, match="no such file"):
        load_usd(tmp_path / "missing.usd", "x")
