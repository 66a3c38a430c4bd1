"""USD import of UsdSkel assets (``.usd``, ``.usda``, ``.usdc``, ``.usdz``) into a `RiggedAsset`.

What becomes of a stage:

- The first ``SkelRoot`` (the default prim's, if it is one) whose skeleton binds at least one mesh.
  Every mesh it binds to that skeleton is merged: points go through ``skel:geomBindTransform``
  into skeleton space, polygons are fan-triangulated (left-handed orientation flipped), joint
  indices are remapped from a mesh's own ``skel:joints`` order, rigid (constant) bindings are
  spread to every point.
- The skeleton's joints, topology, bind transforms and rest transforms (from the bind pose when
  rest transforms are missing); joint names are the ones zooctl wrote (``customData``), else the
  last element of each joint path.
- Every ``SkelAnimation`` on the stage becomes a clip (named by its prim, or the name zooctl
  wrote), sampled at its fps (zooctl's ``customData``, else the stage's timeCodesPerSecond) from
  its first to its last time sample; joints it does not animate keep their rest transform.
- ``upAxis = "Z"`` stages are turned to Y-up; the skeleton prim's world transform is applied;
  ``metersPerUnit`` goes to ``meta["meters_per_unit"]``.
- ``displayColor`` becomes vertex colours, a ``texCoord2f`` primvar ``st`` becomes UVs and a
  bound UsdPreviewSurface's diffuse ``UsdUVTexture`` becomes the texture.
"""

from __future__ import annotations

import os
import re
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from ..asset import Clip, RiggedAsset
from ..errors import InputError
from ..geometry import compose_trs, decompose_trs
from ..limits import check as check_limit

SUFFIXES = (".usd", ".usda", ".usdc", ".usdz")
_Z_UP_TO_Y_UP = np.array([[1.0, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]])


def _bad(path: Path, what: str, hint: str | None = None) -> InputError:
    return InputError(
        f"{path.name}: {what}",
        hint=hint or "export the file again as UsdSkel (SkelRoot, Skeleton, a bound Mesh)",
    )


def _np_matrices(arr) -> np.ndarray:
    """Vt.Matrix4dArray (row-vector) -> (N, 4, 4) column-vector float64."""
    return np.array([np.array(m) for m in arr], dtype=np.float64).reshape(-1, 4, 4).transpose(0, 2, 1)


def load_usd(path: str | Path, name: str) -> RiggedAsset:
    """Read a UsdSkel asset into a validated `RiggedAsset` named ``name``.

    USD's own warnings and errors (dozens of lines for a cyclic sublayer) are trapped, not printed;
    a failure is one `InputError` line. ZOOCTL_DEBUG=1 lets them through."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"no such file: {path}")
    with _trapped_diagnostics():
        try:
            return _load(path, name)
        except InputError as exc:
            if exc.message.startswith(path.name):
                raise
            hint = exc.hint or "export the file again as UsdSkel (SkelRoot, Skeleton, a bound Mesh)"
            raise InputError(f"{path.name}: {exc.message}", hint=hint) from None
        except Exception as exc:  # pxr raises Tf.ErrorException (RuntimeError) with many lines
            raise _bad(path, f"USD could not read it ({_first_line(exc)})", _USD_HINT) from exc


_USD_HINT = "check the file is USD (.usda text, .usdc binary or a .usdz package) that opens in usdview"


def _first_line(exc: BaseException) -> str:
    """The telling part of a pxr error: the commentary of its first (root-cause) error, without
    the C++ function and source location, on one line."""
    for chunk in re.split(r"Error in '", str(exc)):
        m = re.search(r"in file \S+ : '(.*)", chunk, flags=re.S)
        if m:
            return " ".join(m.group(1).strip().rstrip("'").split())[:300]
    lines = [ln.strip() for ln in str(exc).strip().splitlines() if ln.strip()]
    return lines[0][:300] if lines else type(exc).__name__


@contextmanager
def _trapped_diagnostics() -> Iterator[Any]:
    """Keep USD's C++ diagnostics off the terminal: Tf.DiagnosticTrap catches what goes through
    Tf's diagnostic manager, and fd 2 is pointed at /dev/null for anything printed directly."""
    if os.environ.get("ZOOCTL_DEBUG", "") not in ("", "0"):
        yield None
        return
    from pxr import Tf

    trap_cls = getattr(Tf, "DiagnosticTrap", None)  # newer USD releases; fd 2 alone otherwise
    sys.stderr.flush()
    saved = os.dup(2)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, 2)
        if trap_cls is None:
            yield None
        else:
            with trap_cls() as trap:
                try:
                    yield trap
                finally:
                    trap.Clear()
    finally:
        os.dup2(saved, 2)
        os.close(saved)
        os.close(devnull)


def _confined_layers(path: Path) -> None:
    """Open every layer the stage would compose (sublayers, references, payloads, value clips,
    in variants too) one by one and refuse, before USD opens it, one that is outside the file's
    folder after symlinks, missing or not a regular file: a downloaded asset must not make
    zooctl read other files of the user's (the rule glTF URIs follow)."""
    from pxr import Sdf

    folder = path.resolve().parent
    hint = f"keep every layer it uses in {path.name}'s folder (or below), or flatten it into one file"
    todo, seen = [Sdf.Layer.FindOrOpen(str(path))], set()
    while todo:
        layer = todo.pop()
        if layer is None or layer.identifier in seen:
            continue
        seen.add(layer.identifier)
        for what, asset in _layer_arcs(layer):
            if not asset:
                continue
            resolved = layer.ComputeAbsolutePath(asset)
            outer = Path(resolved.split("[", 1)[0])  # a layer inside a .usdz: the package file
            try:
                real = outer.resolve(strict=True)
            except (OSError, RuntimeError):
                raise _bad(path, f"its {what} {asset!r} is missing or cannot be resolved", hint) from None
            if not real.is_relative_to(folder):
                raise _bad(path, f"its {what} {asset!r} is outside the file's folder", hint)
            if not real.is_file():
                raise _bad(path, f"its {what} {asset!r} is not a regular file", hint)
            if what != "value clip":
                todo.append(Sdf.Layer.FindOrOpen(resolved))


def _layer_arcs(layer) -> Iterator[tuple[str, str]]:
    """(kind, asset path) of every arc in ``layer`` that opens another file."""
    from pxr import Sdf

    for sub in layer.subLayerPaths:
        yield "sublayer", sub
    specs: list[Any] = []

    def visit(p) -> None:
        spec = layer.GetObjectAtPath(p)
        if isinstance(spec, Sdf.VariantSpec):
            spec = spec.primSpec
        if isinstance(spec, Sdf.PrimSpec):
            specs.append(spec)

    layer.Traverse(Sdf.Path.absoluteRootPath, visit)
    for spec in specs:
        for ref in spec.referenceList.GetAddedOrExplicitItems():
            yield "reference", ref.assetPath
        for pay in spec.payloadList.GetAddedOrExplicitItems():
            yield "payload", pay.assetPath
        clips = spec.GetInfo("clips") if spec.HasInfo("clips") else {}
        for clip_set in dict(clips).values():
            for a in list(clip_set.get("assetPaths", [])) + [clip_set.get("manifestAssetPath")]:
                if a is not None:
                    yield "value clip", getattr(a, "path", str(a))


def composition_error_line(error: Any) -> str:
    """One line for a USD composition error: a cycle as the chain of layer file names (USD
    prints it over eight lines, with session-layer addresses), anything else squeezed to one."""
    text = str(error).split(" (instantiating", 1)[0]
    if text.startswith("Cycle detected"):
        # "@a@,@anon:...@</P> references: @b@</P> which references: @a@</P> which CANNOT ..."
        # (payloads read the same)
        chain = text.split("CANNOT", 1)[0]
        names = [Path(p).name for p in re.findall(r"@([^@]+)@", chain) if not p.startswith("anon:")]
        if names:
            return "a cycle of references " + " -> ".join(names)
    return " ".join(text.split())[:300]


def _load(path: Path, name: str) -> RiggedAsset:
    from pxr import Usd, UsdGeom, UsdSkel

    _confined_layers(path)
    stage = Usd.Stage.Open(str(path), Usd.Stage.LoadAll)
    if stage is None:
        raise _bad(path, "not a readable USD file", _USD_HINT)
    errors = stage.GetCompositionErrors() if hasattr(stage, "GetCompositionErrors") else []
    if errors:
        raise _bad(
            path,
            f"its layers do not compose: {composition_error_line(errors[0])}",
            "fix the sublayers and references it names (a cycle, a missing file)",
        )
    cache = UsdSkel.Cache()
    found = _find_binding(stage, cache)
    if found is None:
        raise _bad(path, "no UsdSkel skeleton with a bound mesh found")
    skel, skel_query, skinned = found
    _check_joint_paths(path, skel)
    if not skel_query:
        raise _bad(path, f"the skeleton {skel.GetPath()} is invalid")

    topo_parents = np.array(skel_query.GetTopology().GetParentIndices(), dtype=np.int32)
    joints = [str(j) for j in skel_query.GetJointOrder()]
    J = len(joints)
    if J == 0:
        raise _bad(path, "the skeleton has no joints")
    if any(not (-1 <= p < j) for j, p in enumerate(topo_parents)):
        raise _bad(path, "the skeleton's joints are not ordered parents first")
    names = _joint_names(skel, joints)

    bind = skel.GetBindTransformsAttr().Get()
    if bind is None or len(bind) != J:
        raise _bad(path, "the skeleton has no bindTransforms for every joint")
    bind = _np_matrices(bind)
    rest_attr = skel.GetRestTransformsAttr().Get()
    if rest_attr is not None and len(rest_attr) == J:
        rest = _np_matrices(rest_attr)
    else:  # derive the rest pose from the bind pose
        rest = bind.copy()
        for j, p in enumerate(topo_parents):
            if p >= 0:
                rest[j] = np.linalg.inv(bind[p]) @ bind[j]

    # Skeleton space -> zooctl model space (Y up).
    world = _np_matrices(
        [UsdGeom.Xformable(skel.GetPrim()).ComputeLocalToWorldTransform(Usd.TimeCode.Default())]
    )[0]
    if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z:
        world = _Z_UP_TO_Y_UP @ world
    is_root = topo_parents < 0
    rest[is_root] = world @ rest[is_root]
    bind = world @ bind

    verts, faces, sj, sw, colors, uvs, tex = _meshes(path, stage, skinned, joints, world)
    asset = RiggedAsset(
        name=name,
        vertices=verts.astype(np.float32),
        faces=faces.astype(np.int32),
        joint_names=names,
        parents=topo_parents,
        rest_local=rest,
        inverse_bind=np.linalg.inv(bind),
        skin_joints=sj,
        skin_weights=sw,
        uvs=uvs,
        vertex_colors=colors,
        texture_png=tex,
        meta=_meta(stage, path),
    )
    for clip in _clips(stage, cache, joints, rest, is_root, world):
        asset.clips[clip.name] = clip
    return asset.validate()


def _find_binding(stage, cache):
    """(skeleton, skeleton query, [skinning queries]) of the first SkelRoot that skins a mesh."""
    from pxr import Usd, UsdSkel

    roots = []
    default = stage.GetDefaultPrim()
    if default and default.IsA(UsdSkel.Root):
        roots.append(default)
    roots += [p for p in stage.Traverse() if p.IsA(UsdSkel.Root) and p not in roots]
    for prim in roots:
        root = UsdSkel.Root(prim)
        cache.Populate(root, Usd.TraverseInstanceProxies())
        for binding in cache.ComputeSkelBindings(root, Usd.TraverseInstanceProxies()):
            queries = [q for q in binding.GetSkinningTargets() if q.GetPrim().GetTypeName() == "Mesh"]
            if queries:
                skel = binding.GetSkeleton()
                return skel, cache.GetSkelQuery(skel), queries
    return None


def _check_joint_paths(path: Path, skel) -> None:
    """Duplicate joints or a child listed before its parent make UsdSkel's query invalid with
    a C++ error; say which joint is wrong instead."""
    joints = [str(j) for j in (skel.GetJointsAttr().Get() or [])]
    listed = set(joints)
    seen: dict[str, int] = {}
    for i, j in enumerate(joints):
        if j in seen:
            raise _bad(path, f"the skeleton lists joint {j!r} twice (joints {seen[j]} and {i})")
        seen[j] = i
        parent = j.rsplit("/", 1)[0] if "/" in j else None
        while parent is not None and parent not in listed:
            parent = parent.rsplit("/", 1)[0] if "/" in parent else None
        if parent is not None and parent not in seen:
            raise _bad(path, f"the skeleton lists joint {j!r} before its parent {parent!r}")


def _joint_names(skel, joints: list[str]) -> list[str]:
    written = skel.GetPrim().GetCustomDataByKey("zooctl:jointNames")
    if written is not None and len(written) == len(joints) and len(set(written)) == len(joints):
        return [str(n) for n in written]
    names = [j.rsplit("/", 1)[-1] for j in joints]
    if len(set(names)) != len(names):
        names = [j.replace("/", "__") for j in joints]
    return names


def _meshes(path: Path, stage, queries, joints: list[str], world: np.ndarray):
    """Merge the skinned meshes: vertices (V, 3), faces (F, 3), sparse weights, colours, UVs, texture."""
    from pxr import Usd, UsdGeom

    index_of = {j: i for i, j in enumerate(joints)}
    all_v, all_f, all_w, all_c, all_uv = [], [], [], [], []
    texture = None
    offset = 0
    for q in queries:
        mesh = UsdGeom.Mesh(q.GetPrim())
        pts = mesh.GetPointsAttr().Get(Usd.TimeCode.Default())
        counts = mesh.GetFaceVertexCountsAttr().Get()
        idx = mesh.GetFaceVertexIndicesAttr().Get()
        if pts is None or counts is None or idx is None or len(pts) == 0:
            continue
        check_limit("the skinned meshes have", offset + len(pts), "max_vertices", " points")
        check_limit(f"mesh {q.GetPrim().GetPath()} has", len(idx), "max_elements", " face corners")
        v = np.array(pts, dtype=np.float64)
        if not np.all(np.isfinite(v)):
            raise _bad(path, f"mesh {q.GetPrim().GetPath()} has points that are NaN or infinite")
        gb = _np_matrices([q.GetGeomBindTransform(Usd.TimeCode.Default())])[0]
        v = (world @ gb @ np.c_[v, np.ones(len(v))].T).T[:, :3]
        faces = _triangulate(path, np.array(counts, dtype=np.int64), np.array(idx, dtype=np.int64), len(v))
        if mesh.GetOrientationAttr().Get() == UsdGeom.Tokens.leftHanded:
            faces = faces[:, ::-1]
        jidx, jw = _weights(path, q, len(v), index_of)
        all_v.append(v)
        all_f.append(faces + offset)
        all_w.append((jidx, jw))
        all_c.append(_vertex_primvar(mesh, "displayColor", len(v), 3))
        all_uv.append(_vertex_primvar(mesh, "st", len(v), 2))
        texture = texture or _texture(q.GetPrim(), path.resolve().parent)
        offset += len(v)
    if not all_v:
        raise _bad(path, "the skinned meshes have no points or faces")
    K = max(w.shape[1] for _, w in all_w)
    sj = np.concatenate([np.pad(j, ((0, 0), (0, K - j.shape[1]))) for j, _ in all_w])
    sw = np.concatenate([np.pad(w, ((0, 0), (0, K - w.shape[1]))) for _, w in all_w])
    sj, sw = _merge_influences(sj, sw)
    if np.any(sw.sum(1) <= 0):
        raise _bad(path, f"{int((sw.sum(1) <= 0).sum())} points have no skin weight")
    sj, sw = _strongest(sj, sw, min(K, 8))
    colors = None
    if all(c is not None for c in all_c):
        colors = np.clip(np.concatenate(all_c), 0, 1).astype(np.float32)
    uvs = None
    if all(u is not None for u in all_uv):
        uvs = np.concatenate(all_uv).astype(np.float32)
        uvs[:, 1] = 1.0 - uvs[:, 1]  # USD's v runs up the image, zooctl's (glTF's) down
    return (
        np.concatenate(all_v),
        np.concatenate(all_f),
        sj,
        sw,
        colors,
        uvs,
        texture if uvs is not None else None,
    )


def _merge_influences(sj: np.ndarray, sw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sum the weights of a joint named twice in one point's influences, in (V, K) arrays: a
    dense (points x joints) matrix would take gigabytes for a large mesh on a large skeleton."""
    V, K = sj.shape
    order = np.argsort(sj, axis=1, kind="stable")
    j = np.take_along_axis(sj, order, 1)
    w = np.take_along_axis(sw, order, 1)
    first = np.ones((V, K), dtype=bool)
    first[:, 1:] = j[:, 1:] != j[:, :-1]
    group = np.cumsum(first, axis=1) - 1
    rows = np.broadcast_to(np.arange(V)[:, None], (V, K))
    merged_w = np.zeros((V, K))
    np.add.at(merged_w, (rows, group), w)
    merged_j = np.zeros((V, K), dtype=np.int64)
    merged_j[rows[first], group[first]] = j[first]
    return merged_j, merged_w


def _strongest(sj: np.ndarray, sw: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The k strongest influences of each point, renormalised, sorted by decreasing weight."""
    order = np.argsort(-sw, axis=1, kind="stable")[:, :k]
    w = np.take_along_axis(sw, order, 1)
    j = np.take_along_axis(sj, order, 1)
    w = w / w.sum(1, keepdims=True)
    j[w == 0] = 0
    return j.astype(np.int32), w.astype(np.float32)


def _triangulate(path: Path, counts: np.ndarray, idx: np.ndarray, nverts: int) -> np.ndarray:
    if counts.sum() != len(idx) or np.any(counts < 3):
        raise _bad(path, "faceVertexCounts and faceVertexIndices do not agree")
    if len(idx) and (idx.min() < 0 or idx.max() >= nverts):
        raise _bad(path, "face vertex indices out of range")
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    tris = []
    for k in range(1, int(counts.max()) - 1):  # fan: (0, k, k+1) for every face with > k+1 corners
        sel = counts > k + 1
        s = starts[sel]
        tris.append(np.stack([idx[s], idx[s + k], idx[s + k + 1]], 1))
    return np.concatenate(tris) if tris else np.zeros((0, 3), np.int64)


def _weights(path: Path, q, nverts: int, index_of: dict[str, int]) -> tuple[np.ndarray, np.ndarray]:
    """(V, K) skeleton joint indices and weights of one mesh's skinning query."""
    from pxr import Usd

    try:
        ji, jw = q.ComputeJointInfluences(Usd.TimeCode.Default())
    except Exception:  # pxr raises on malformed primvars
        ji, jw = None, None
    if ji is None or len(ji) == 0:
        raise _bad(path, f"mesh {q.GetPrim().GetPath()} has no skel:jointIndices / skel:jointWeights")
    K = q.GetNumInfluencesPerComponent()
    ji = np.array(ji, dtype=np.int64).reshape(-1, K)
    jw = np.array(jw, dtype=np.float64).reshape(-1, K)
    if q.IsRigidlyDeformed():
        ji, jw = np.repeat(ji[:1], nverts, 0), np.repeat(jw[:1], nverts, 0)
    if len(ji) != nverts:
        raise _bad(path, f"mesh {q.GetPrim().GetPath()} has {len(ji)} skin influences for {nverts} points")
    order = q.GetJointOrder()
    if order:  # the mesh's own skel:joints order -> the skeleton's
        try:
            remap = np.array([index_of[str(j)] for j in order], dtype=np.int64)
        except KeyError as exc:
            raise _bad(
                path, f"mesh {q.GetPrim().GetPath()} names joint {exc.args[0]!r} that the skeleton lacks"
            ) from None
        if ji.size and (ji.min() < 0 or ji.max() >= len(remap)):
            raise _bad(path, "skel:jointIndices out of range")
        ji = remap[ji]
    elif ji.size and (ji.min() < 0 or ji.max() >= len(index_of)):
        raise _bad(path, "skel:jointIndices out of range")
    return ji, np.clip(np.nan_to_num(jw), 0, None)


def _vertex_primvar(mesh, name: str, nverts: int, width: int) -> np.ndarray | None:
    """A per-vertex (V, width) array of a primvar (constant, uniform-free); None when absent."""
    from pxr import UsdGeom

    pv = UsdGeom.PrimvarsAPI(mesh).GetPrimvar(name)
    if not pv or not pv.HasValue():
        return None
    val = pv.ComputeFlattened()
    if val is None or len(val) == 0:
        return None
    a = np.array(val, dtype=np.float64).reshape(-1, width)
    interp = pv.GetInterpolation()
    if interp == UsdGeom.Tokens.constant:
        return np.repeat(a[:1], nverts, 0)
    if interp in (UsdGeom.Tokens.vertex, UsdGeom.Tokens.varying) and len(a) == nverts:
        return a
    if interp == UsdGeom.Tokens.faceVarying:
        idx = np.array(mesh.GetFaceVertexIndicesAttr().Get(), dtype=np.int64)
        if len(idx) == len(a):  # average the corners that share a vertex
            out = np.zeros((nverts, width))
            n = np.zeros(nverts)
            np.add.at(out, idx, a)
            np.add.at(n, idx, 1)
            return out / np.maximum(n, 1)[:, None]
    return None


def _texture(prim, folder: Path) -> bytes | None:
    """The PNG/JPEG bytes of the diffuse UsdUVTexture of the prim's bound material, if any; only
    a file inside the USD file's folder (or its package) is read, as for glTF."""
    from pxr import Ar, Usd, UsdShade

    mat, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
    if not mat:
        return None
    for shader_prim in Usd.PrimRange(mat.GetPrim()):
        shader = UsdShade.Shader(shader_prim)
        if not shader or shader.GetIdAttr().Get() != "UsdUVTexture":
            continue
        f = shader.GetInput("file")
        asset_path = f.Get() if f else None
        resolved = getattr(asset_path, "resolvedPath", "") if asset_path is not None else ""
        if not resolved or not Path(resolved.split("[", 1)[0]).resolve().is_relative_to(folder):
            continue
        data = Ar.GetResolver().OpenAsset(Ar.ResolvedPath(resolved))
        if data is None:
            continue
        blob = bytes(data.GetBuffer())
        return _as_png(blob)
    return None


def _as_png(blob: bytes) -> bytes | None:
    if blob[:8] == b"\x89PNG\r\n\x1a\n":
        return blob
    try:
        import io

        from PIL import Image

        buf = io.BytesIO()
        Image.open(io.BytesIO(blob)).convert("RGB").save(buf, format="PNG")
        return buf.getvalue()
    except Exception:
        return None


def _clips(
    stage, cache, joints: list[str], rest: np.ndarray, is_root: np.ndarray, world: np.ndarray
) -> list[Clip]:
    from pxr import Usd, UsdSkel

    tcps = float(stage.GetTimeCodesPerSecond() or 24.0)
    if not (np.isfinite(tcps) and tcps > 0):
        raise InputError(f"the stage's timeCodesPerSecond is {tcps}; it must be positive")
    total_frames = 0
    rest_t, rest_q, rest_s = decompose_trs(rest)
    index_of = {j: i for i, j in enumerate(joints)}
    out: list[Clip] = []
    taken: set[str] = set()
    for prim in stage.Traverse(Usd.TraverseInstanceProxies()):
        if not prim.IsA(UsdSkel.Animation):
            continue
        anim = UsdSkel.Animation(prim)
        aq = cache.GetAnimQuery(anim)
        if not aq:
            continue
        anim_joints = [str(j) for j in aq.GetJointOrder()]
        cols = [index_of.get(j, -1) for j in anim_joints]
        if not any(c >= 0 for c in cols):
            continue  # an animation of another skeleton
        name = str(prim.GetCustomDataByKey("zooctl:clip") or prim.GetName())
        base, k = name, 1
        while name in taken:
            name, k = f"{base}_{k}", k + 1
        taken.add(name)
        fps = float(prim.GetCustomDataByKey("zooctl:fps") or tcps)
        if not (np.isfinite(fps) and fps > 0):
            raise InputError(f"animation {name!r} has fps {fps}; it must be positive")
        samples = sorted(aq.GetJointTransformTimeSamples())
        if samples:
            check_limit(
                f"animation {name!r} lasts", (samples[-1] - samples[0]) / tcps, "max_clip_seconds", " s"
            )
            n = int(round((samples[-1] - samples[0]) / tcps * fps)) + 1
            total_frames += n
            check_limit("the animations have", total_frames, "max_frames", " frames")
            check_limit("the animations have", total_frames * len(joints), "max_elements", " joint-frames")
            times = [samples[0] + i * tcps / fps for i in range(n)]
        else:
            times = [Usd.TimeCode.Default()]
        T = len(times)
        t = np.repeat(rest_t[None], T, 0)
        q = np.repeat(rest_q[None], T, 0)
        s = np.repeat(rest_s[None], T, 0)
        sel = np.array([i for i, c in enumerate(cols) if c >= 0])
        dst = np.array([cols[i] for i in sel])
        for f, time in enumerate(times):
            tr, rot, sc = aq.ComputeJointLocalTransformComponents(time)
            tr = np.array(tr, dtype=np.float64).reshape(-1, 3)
            # Gf.Quatf arrays convert to numpy imaginary part first: xyzw -> wxyz.
            rot = np.array(rot, dtype=np.float64).reshape(-1, 4)[:, [3, 0, 1, 2]]
            sc = np.array(sc, dtype=np.float64).reshape(-1, 3)
            t[f, dst], q[f, dst], s[f, dst] = tr[sel], rot[sel], sc[sel]
        if np.any(is_root) and not np.allclose(world, np.eye(4)):
            _apply_world_to_roots(t, q, s, is_root, world)
        out.append(Clip(name, fps, q / np.linalg.norm(q, axis=-1, keepdims=True), t, s))
    return out


def _apply_world_to_roots(
    t: np.ndarray, q: np.ndarray, s: np.ndarray, is_root: np.ndarray, world: np.ndarray
) -> None:
    """Pre-multiply the root joints' animated local transforms by ``world`` (in place)."""
    local = compose_trs(t[:, is_root], q[:, is_root], s[:, is_root])
    nt, nq, ns = decompose_trs(world @ local)
    t[:, is_root], q[:, is_root], s[:, is_root] = nt, nq, ns


def _meta(stage, path: Path) -> dict[str, Any]:
    from pxr import UsdGeom

    meta: dict[str, Any] = {
        "meters_per_unit": float(UsdGeom.GetStageMetersPerUnit(stage)),
        "source": path.name,
    }
    info = stage.GetRootLayer().customLayerData.get("zooctl", {})
    for key in ("license", "source"):
        if info.get(key):
            meta[key] = str(info[key])
    if info.get("tags"):
        meta["tags"] = [str(t) for t in info["tags"]]
    return meta
