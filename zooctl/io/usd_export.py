"""USD export of a rigged asset as UsdSkel: ``.usd``/``.usdc`` (binary), ``.usda`` (text), ``.usdz``.

Stage layout (``N`` is the asset name made a valid USD identifier)::

    /N                 SkelRoot, the default prim; variant set "animation" picks the bound clip
    /N/Skeleton        Skeleton: joints (paths such as "hips/spine1"), bindTransforms (joint to
                       skeleton space at bind time), restTransforms (local rest pose)
    /N/Mesh            Mesh with SkelBindingAPI: skel:jointIndices / skel:jointWeights primvars
                       (vertex, elementSize K), skel:geomBindTransform (identity: the points are
                       already in bind space), displayColor
/N/Looks/Material  UsdPreviewSurface: its diffuseColor a UsdUVTexture (the asset's texture, beside
                   the layer) or, for vertex colours, a UsdPrimvarReader_float3 of displayColor
    /N/Animations/C    one SkelAnimation per clip; time code i * timeCodesPerSecond / fps is frame i
    /Camera            an optional UsdGeom.Camera

Units and axes: ``upAxis = "Y"``, ``metersPerUnit`` from ``asset.meta["meters_per_unit"]`` (1 by
default), and ``timeCodesPerSecond`` is the first exported clip's fps. USD matrices act on row
vectors, so every zooctl (column-vector) matrix is written transposed.

A joint whose local transform stays at its rest transform in every exported clip is left out of the
SkelAnimations (UsdSkel then uses the rest transform, stored in double precision); this keeps
large constant scales such as a 100x armature node out of UsdSkel's half-precision ``scales``.
"""

from __future__ import annotations

import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..asset import RiggedAsset
from ..errors import InputError, UsageError
from ..store.fs import publish, temp_path

SUFFIXES = (".usd", ".usda", ".usdc", ".usdz")
ANIMATION_VARIANT_SET = "animation"
_STATIC_TOL = 1e-7


def _identifier(name: str) -> str:
    from pxr import Tf

    return Tf.MakeValidIdentifier(name) or "_"


def joint_paths(names: Sequence[str], parents: np.ndarray) -> list[str]:
    """UsdSkel joint paths ("root/child/grandchild") with names made valid and unique per parent."""
    paths: list[str] = []
    taken: set[str] = set()
    for name, p in zip(names, parents, strict=True):
        base = _identifier(name)
        prefix = "" if p < 0 else paths[p] + "/"
        cand, k = prefix + base, 1
        while cand in taken:
            cand, k = f"{prefix}{base}_{k}", k + 1
        taken.add(cand)
        paths.append(cand)
    return paths


def select_clips(asset: RiggedAsset, clips: Sequence[str] | None) -> list[str]:
    """The clip names to export (all when ``clips`` is None); an unknown name is a usage error."""
    if clips is None:
        return list(asset.clips)
    missing = [c for c in clips if c not in asset.clips]
    if missing:
        raise UsageError(
            f"asset {asset.name!r} has no clip {missing[0]!r}",
            hint=f"clips: {', '.join(asset.clips) or 'none'}",
        )
    return list(dict.fromkeys(clips))


def _matrices(mats: np.ndarray):
    from pxr import Gf, Vt

    return Vt.Matrix4dArray([Gf.Matrix4d(m.T.tolist()) for m in np.asarray(mats, dtype=np.float64)])


def save_usd(
    asset: RiggedAsset,
    path: str | Path,
    clips: Sequence[str] | None = None,
    camera: Any | None = None,
    camera_index: int = 0,
) -> Path:
    """Write ``asset`` with the named clips (``None``: all) to ``path``; the suffix picks the format.

    ``camera`` is an optional `zooctl.render.camera.Camera` (its ``camera_index``-th camera) written
    as ``/Camera``. Writes atomically: a temporary beside ``path``, then ``os.replace``.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in SUFFIXES:
        raise UsageError(f"cannot write USD to {path.name!r}", hint=f"use one of {', '.join(SUFFIXES)}")
    asset.validate()
    names = select_clips(asset, clips)
    tex_name = f"{path.stem}.texture.png" if asset.texture_png is not None else None
    if suffix == ".usdz":
        with tempfile.TemporaryDirectory(
            prefix=".zooctl-usdz-", dir=path.parent if path.parent.exists() else None
        ) as d:
            layer = Path(d) / f"{path.stem}.usdc"
            if tex_name:
                (Path(d) / tex_name).write_bytes(asset.texture_png)
            _write_stage(asset, layer, names, tex_name, camera, camera_index)
            _publish_usdz(layer, path)
        return path
    tmp = temp_path(path)
    tmp_usd = tmp.with_name(tmp.name + suffix)  # USD picks the file format from the suffix
    tmp.unlink(missing_ok=True)
    try:
        if tex_name:
            # The texture goes beside the layer (referenced relatively); published first.
            tex_tmp = temp_path(path.parent / tex_name)
            tex_tmp.write_bytes(asset.texture_png)
            publish(tex_tmp, path.parent / tex_name)
        _write_stage(
            asset,
            tmp_usd,
            names,
            tex_name,
            camera,
            camera_index,
            usd_format="usdc" if suffix == ".usd" else None,
        )
        publish(tmp_usd, path)
    except BaseException:
        tmp_usd.unlink(missing_ok=True)
        raise
    return path


def _publish_usdz(layer: Path, path: Path) -> None:
    import errno

    from pxr import Tf, UsdUtils

    tmp = temp_path(path)
    tmp_usdz = tmp.with_name(tmp.name + ".usdz")
    tmp.unlink(missing_ok=True)
    try:
        try:
            packaged = UsdUtils.CreateNewUsdzPackage(str(layer), str(tmp_usdz))
        except Tf.ErrorException:
            packaged = False
        if not packaged:  # its inputs were just written by us: the output is what failed
            raise OSError(errno.EIO, "USD could not write the package (is the disk full?)", str(path))
        publish(tmp_usdz, path)
    except BaseException:
        tmp_usdz.unlink(missing_ok=True)
        raise


def _write_stage(
    asset: RiggedAsset,
    path: Path,
    clip_names: list[str],
    texture_file: str | None,
    camera: Any | None,
    camera_index: int,
    usd_format: str | None = None,
) -> None:
    from pxr import Sdf, Usd, UsdGeom, UsdSkel, Vt

    layer = Sdf.Layer.CreateNew(str(path), args={"format": usd_format} if usd_format else {})
    if layer is None:
        raise InputError(f"cannot create a USD layer at {path}")
    stage = Usd.Stage.Open(layer)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, float(asset.meta.get("meters_per_unit", 1.0)))
    fps = float(asset.clips[clip_names[0]].fps) if clip_names else 30.0
    stage.SetTimeCodesPerSecond(fps)
    stage.SetFramesPerSecond(fps)
    if clip_names:
        first = asset.clips[clip_names[0]]
        stage.SetStartTimeCode(0)
        stage.SetEndTimeCode((first.num_frames - 1) * fps / first.fps)
    layer.customLayerData = {
        "zooctl": {
            "asset": asset.name,
            "license": str(asset.meta.get("license", "")),
            "source": str(asset.meta.get("source", "")),
            "tags": Vt.StringArray([str(t) for t in asset.meta.get("tags", [])]),
        }
    }

    root_path = Sdf.Path("/" + _identifier(asset.name))
    root = UsdSkel.Root.Define(stage, root_path)
    stage.SetDefaultPrim(root.GetPrim())
    Usd.ModelAPI(root.GetPrim()).SetKind("component")

    skel = UsdSkel.Skeleton.Define(stage, root_path.AppendChild("Skeleton"))
    paths = joint_paths(asset.joint_names, asset.parents)
    skel.CreateJointsAttr(Vt.TokenArray(paths))
    skel.CreateJointNamesAttr(Vt.TokenArray([_identifier(n) for n in asset.joint_names]))
    bind_world = np.linalg.inv(asset.inverse_bind)
    skel.CreateBindTransformsAttr(_matrices(bind_world))
    skel.CreateRestTransformsAttr(_matrices(asset.rest_local))
    skel.GetPrim().SetCustomDataByKey("zooctl:jointNames", Vt.StringArray(list(asset.joint_names)))
    skel_binding = UsdSkel.BindingAPI.Apply(skel.GetPrim())

    mesh = _write_mesh(stage, root_path.AppendChild("Mesh"), asset, skel, texture_file)
    extent = UsdGeom.Boundable.ComputeExtentFromPlugins(mesh, Usd.TimeCode.Default())
    root.CreateExtentAttr(extent)

    if clip_names:
        UsdGeom.Scope.Define(stage, root_path.AppendChild("Animations"))
        anim_paths = []
        # Also key the joints whose rest pose differs from the bind pose: UsdSkel would use the
        # rest transform for them, but Blender's importer takes the bind pose.
        joints = np.union1d(animated_joints(asset, clip_names), np.nonzero(rest_differs_from_bind(asset))[0])
        for name in clip_names:
            anim_path = root_path.AppendChild("Animations").AppendChild(
                _unique_child(stage, root_path.AppendChild("Animations"), name)
            )
            _write_animation(stage, anim_path, asset, name, paths, fps, joints)
            anim_paths.append((name, anim_path))
        # One variant per clip binds that clip; the first one is selected.
        vset = root.GetPrim().GetVariantSets().AddVariantSet(ANIMATION_VARIANT_SET)
        for name, anim_path in anim_paths:
            variant = _identifier(name)
            vset.AddVariant(variant)
            vset.SetVariantSelection(variant)
            with vset.GetVariantEditContext():
                skel_binding.CreateAnimationSourceRel().SetTargets([anim_path])
        vset.SetVariantSelection(_identifier(anim_paths[0][0]))

    if camera is not None:
        _write_camera(stage, camera, camera_index)
    _save_layer(layer, path)


def _save_layer(layer, path: Path) -> None:
    """``layer.Save()``, its failure (a full disk: USD raises its own error, not an OSError) an
    OSError the exporters' caller reports as one line."""
    import errno
    import re

    from pxr import Tf

    why = "USD could not write the file"
    try:
        saved = layer.Save()
    except Tf.ErrorException as exc:
        found = re.findall(r": '([^']+)'", str(exc))
        saved, why = False, f"{why}: {found[0]}" if found else why
    if not saved:
        raise OSError(errno.EIO, f"{why} (is the disk full?)", str(path))


def _unique_child(stage, parent, name: str) -> str:
    base = _identifier(name)
    cand, k = base, 1
    while stage.GetPrimAtPath(parent.AppendChild(cand)):
        cand, k = f"{base}_{k}", k + 1
    return cand


def _write_mesh(stage, path, asset: RiggedAsset, skel, texture_file: str | None):
    from pxr import Gf, Sdf, UsdGeom, UsdSkel, Vt

    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(asset.vertices, dtype=np.float32)))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(asset.num_faces, 3, dtype=np.int32)))
    mesh.CreateFaceVertexIndicesAttr(
        Vt.IntArray.FromNumpy(np.ascontiguousarray(asset.faces.reshape(-1), dtype=np.int32))
    )
    mesh.CreateExtentAttr(UsdGeom.PointBased.ComputeExtent(mesh.GetPointsAttr().Get()))
    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
    K = int(asset.skin_joints.shape[1])
    binding.CreateJointIndicesPrimvar(False, K).Set(
        Vt.IntArray.FromNumpy(np.ascontiguousarray(asset.skin_joints.reshape(-1), dtype=np.int32))
    )
    binding.CreateJointWeightsPrimvar(False, K).Set(
        Vt.FloatArray.FromNumpy(np.ascontiguousarray(asset.skin_weights.reshape(-1), dtype=np.float32))
    )
    binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))
    pv = UsdGeom.PrimvarsAPI(mesh)
    if asset.vertex_colors is not None:
        col = mesh.CreateDisplayColorPrimvar(UsdGeom.Tokens.vertex)
        col.Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(asset.vertex_colors, dtype=np.float32)))
    if asset.uvs is not None:
        st = pv.CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
        uv = np.asarray(asset.uvs, dtype=np.float32).copy()
        uv[:, 1] = 1.0 - uv[:, 1]  # glTF's v runs down the image, USD's up
        st.Set(Vt.Vec2fArray.FromNumpy(uv))
    if texture_file is not None and asset.uvs is not None:
        _write_material(stage, path.GetParentPath().AppendChild("Looks"), mesh, texture_file)
    elif asset.vertex_colors is not None:
        _write_material(stage, path.GetParentPath().AppendChild("Looks"), mesh, None)
    return mesh


def _write_material(stage, looks_path, mesh, texture_file: str | None) -> None:
    """A UsdPreviewSurface bound to ``mesh`` whose diffuse colour is ``texture_file`` (sRGB, read
    at the ``st`` primvar) or, without one, the ``displayColor`` primvar (a renderer that shows
    only materials shows the vertex colours too)."""
    from pxr import Sdf, UsdGeom, UsdShade

    UsdGeom.Scope.Define(stage, looks_path)
    mat = UsdShade.Material.Define(stage, looks_path.AppendChild("Material"))
    surf = UsdShade.Shader.Define(stage, mat.GetPath().AppendChild("PreviewSurface"))
    surf.CreateIdAttr("UsdPreviewSurface")
    surf.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.8)
    surf.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(0.0)
    diffuse = surf.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f)
    if texture_file is None:
        colour = UsdShade.Shader.Define(stage, mat.GetPath().AppendChild("DisplayColorReader"))
        colour.CreateIdAttr("UsdPrimvarReader_float3")
        colour.CreateInput("varname", Sdf.ValueTypeNames.String).Set("displayColor")
        colour.CreateInput("fallback", Sdf.ValueTypeNames.Float3).Set((0.18, 0.18, 0.18))
        diffuse.ConnectToSource(colour.CreateOutput("result", Sdf.ValueTypeNames.Float3))
    else:
        reader = UsdShade.Shader.Define(stage, mat.GetPath().AppendChild("StReader"))
        reader.CreateIdAttr("UsdPrimvarReader_float2")
        reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
        tex = UsdShade.Shader.Define(stage, mat.GetPath().AppendChild("BaseColor"))
        tex.CreateIdAttr("UsdUVTexture")
        tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath("./" + texture_file))
        tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("sRGB")
        tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
        reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
        diffuse.ConnectToSource(tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3))
    mat.CreateSurfaceOutput().ConnectToSource(surf.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(mat)


def animated_joints(asset: RiggedAsset, clip_names: Sequence[str]) -> np.ndarray:
    """Indices of the joints whose local transform leaves its rest transform in any of the clips.

    Every exported clip animates all of them (not only its own), so that a tool switching from one
    clip to another (Blender keeps the last value of an unkeyed bone) always gets the full pose.
    """
    scale = max(asset.size(), 1e-12)
    moving = np.zeros(asset.num_joints, dtype=bool)
    for name in clip_names:
        diff = np.abs(asset.clips[name].local_matrices() - asset.rest_local[None])
        diff[..., :3, 3] /= scale  # translations relative to the model's size
        moving |= diff.reshape(len(diff), asset.num_joints, -1).max(axis=(0, 2)) > _STATIC_TOL
    joints = np.nonzero(moving)[0]
    return joints if len(joints) else np.arange(min(1, asset.num_joints))  # never an empty animation


def bind_locals(asset: RiggedAsset) -> np.ndarray:
    """(J, 4, 4) the local transforms of the bind pose (from the inverse bind matrices)."""
    bind = np.linalg.inv(asset.inverse_bind)
    local = bind.copy()
    for j, p in enumerate(asset.parents):
        if p >= 0:
            local[j] = np.linalg.inv(bind[p]) @ bind[j]
    return local


def rest_differs_from_bind(asset: RiggedAsset) -> np.ndarray:
    """(J,) bool: joints whose rest local transform is not their bind-pose local transform."""
    diff = np.abs(bind_locals(asset) - asset.rest_local)
    diff[:, :3, 3] /= max(asset.size(), 1e-12)
    return diff.reshape(asset.num_joints, -1).max(1) > _STATIC_TOL * 10


def _write_animation(
    stage, path, asset: RiggedAsset, clip_name: str, paths: list[str], tcps: float, joints: np.ndarray
) -> None:
    from pxr import UsdSkel, Vt

    c = asset.clips[clip_name]
    anim = UsdSkel.Animation.Define(stage, path)
    anim.GetPrim().SetCustomDataByKey("zooctl:clip", clip_name)
    anim.GetPrim().SetCustomDataByKey("zooctl:fps", float(c.fps))
    anim.CreateJointsAttr(Vt.TokenArray([paths[j] for j in joints]))
    t_attr = anim.CreateTranslationsAttr()
    r_attr = anim.CreateRotationsAttr()
    s_attr = anim.CreateScalesAttr()
    trans = np.ascontiguousarray(c.translations[:, joints], dtype=np.float32)
    # wxyz -> xyzw: Gf.Quatf stores its imaginary part first, which is what FromNumpy reads.
    rots = np.ascontiguousarray(_continuous(c.rotations[:, joints])[..., [1, 2, 3, 0]], dtype=np.float32)
    scales = np.ascontiguousarray(c.scales[:, joints], dtype=np.float16)
    for i in range(c.num_frames):
        t = i * tcps / c.fps
        t_attr.Set(Vt.Vec3fArray.FromNumpy(trans[i]), t)
        r_attr.Set(Vt.QuatfArray.FromNumpy(rots[i]), t)
        s_attr.Set(Vt.Vec3hArray.FromNumpy(scales[i]), t)


def _continuous(q: np.ndarray) -> np.ndarray:
    """(T, J, 4) quaternions with signs flipped so consecutive frames are on the same hemisphere
    (USD interpolates between time samples without taking the shortest path)."""
    q = np.array(q, dtype=np.float64)
    for i in range(1, len(q)):
        flip = np.sum(q[i] * q[i - 1], axis=-1) < 0
        q[i, flip] *= -1
    return q


def _write_camera(stage, camera: Any, index: int) -> None:
    from pxr import Gf, UsdGeom

    from ..render.camera import to_usd

    attrs = to_usd(camera, index)
    cam = UsdGeom.Camera.Define(stage, "/Camera")
    cam.CreateFocalLengthAttr(attrs["focal_length"])
    cam.CreateHorizontalApertureAttr(attrs["horizontal_aperture"])
    cam.CreateVerticalApertureAttr(attrs["vertical_aperture"])
    cam.CreateHorizontalApertureOffsetAttr(attrs["horizontal_aperture_offset"])
    cam.CreateVerticalApertureOffsetAttr(attrs["vertical_aperture_offset"])
    UsdGeom.Xformable(cam).AddTransformOp().Set(Gf.Matrix4d(np.asarray(attrs["camera_to_world"]).T.tolist()))
