"""PlanetZoo-style test videos rendered from bank assets, with ground truth (CASA section 4).

For each asset, the motion (``motion``): ``random`` (the default), every 12 frames 8 random bones
get a new random rotation (slerped between those keyframes) and the others hold still; or
``clips``, one of the asset's own clips (`clip_motion`: drawn by the seed, resampled to the
video's frame rate, played forwards and backwards, the root joints at their rest translation), an
artist's motion in which the bones move as the animal does (an asset without clips gets
``random``). The camera orbits the animal, its azimuth moving by 15 to 22.5 degrees every 12
frames; the light direction, ambient level and background are random. The background is still in
the frame (``background="still"``, the default) or a distant scene fixed in the world that moves
in the frame as the camera orbits (``world``). With ``turn`` the animal also turns in the world
about the vertical through its centre, steadily, by that many degrees over the clip (the sign
drawn by the seed), as an animal walking a bend does; without it the animal holds its heading.
Saved per video, in ``DIR/<name>/``:

- ``video.npz``: frames (T, H, W, 3) uint8, masks (T, H, W) bool, flow (T-1, H, W, 2) float16
  (exact forward flow of the rendered surface), flow_valid (T-1, H, W) bool, intrinsics (4,)
  fx, fy, cx, cy; ground truth ``gt_vertices`` (T, V, 3) world, ``gt_faces`` (F, 3),
  ``gt_joints`` (T, J, 3) world joint origins, ``gt_parents`` (J,), ``gt_skin_joints`` and
  ``gt_skin_weights`` (V, K), ``gt_cam_rotation`` (T, 3, 3) and ``gt_cam_translation`` (T, 3)
  world-to-camera, ``gt_novel_vertices`` (V, 3) a held-out pose (12 frames after the last one of
  the motion, for re-animation) seen by the last frame's camera (OpenCV convention, `zooctl.render.camera`);
  ``gt_view_masks`` (C, T, H, W) bool, ``gt_view_rotation`` (C, T, 3, 3) and ``gt_view_translation``
  (C, T, 3): the same frames seen by C = 2 cameras the fit never sees (`NOVEL_VIEWS`: the input
  camera turned +90 degrees in azimuth, and raised 35 degrees in elevation), masks only; with
  ``appearance="textured"`` (`zooctl.benchdata.appearance`: a procedural coat over a natural-looking
  scene instead of flat colours over a gradient) also ``gt_view_frames`` (C, T, H, W, 3) uint8,
  what those cameras see of the animal (black around it);
- ``meta.json``: asset name, frames, size, fps, seed, the vertical field of view (``fov``), motion
  (and the clip), ``appearance`` for a textured video, ``background`` for a ``world`` one, ``turn``
  (signed degrees) for a turning one; ``video.mp4``: the frames as H.264.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
import torch

from ..asset import RiggedAsset
from ..errors import UsageError
from ..geometry import compose_trs, quat_normalize, quat_slerp, quat_to_matrix
from ..retrieval.evaluate import plan_label
from ..store.fs import write_bytes_atomic, write_json_atomic
from .appearance import APPEARANCES, Coat, natural_background, world_backgrounds

KEY_EVERY = 12
BONES_PER_KEY = 8
# (azimuth, elevation) offsets in degrees of the held-out cameras from each frame's input camera.
NOVEL_VIEWS = ((90.0, 0.0), (0.0, 35.0))
BACKGROUNDS = ("still", "world")


def _random_quat(rng: np.random.Generator, max_deg: float) -> np.ndarray:
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    ang = math.radians(rng.uniform(0.3, 1.0) * max_deg)
    return np.concatenate(([math.cos(ang / 2)], math.sin(ang / 2) * axis))


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ]
    )


def random_motion(
    asset: RiggedAsset, frames: int, rng: np.random.Generator, max_deg: float = 35.0
) -> np.ndarray:
    """(T, J, 4, 4) local transforms: the rest pose with 8 random bones re-rotated every 12 frames."""
    t, q, s = asset.rest_trs()
    dense = asset.skin_weights_dense()
    movable = [j for j in range(asset.num_joints) if asset.parents[j] >= 0 and dense[:, j].sum() > 0]
    keys = list(range(0, frames, KEY_EVERY))
    if keys[-1] != frames - 1 and frames > 1:
        keys.append(frames - 1)
    key_q = []
    cur = q.copy()
    for _ in keys:
        cur = cur.copy()
        if movable:
            for j in rng.choice(movable, min(BONES_PER_KEY, len(movable)), replace=False):
                cur[j] = _qmul(q[j], _random_quat(rng, max_deg))  # a random rotation relative to rest
        key_q.append(cur)
    rot = np.zeros((frames, asset.num_joints, 4))
    for i in range(frames):
        k = max(0, int(np.searchsorted(keys, i, side="right")) - 1)
        if k >= len(keys) - 1:
            rot[i] = key_q[-1]
        else:
            a = (i - keys[k]) / (keys[k + 1] - keys[k])
            rot[i] = quat_slerp(key_q[k], key_q[k + 1], a)
    rot = quat_normalize(rot)
    return compose_trs(
        np.broadcast_to(t, rot.shape[:-1] + (3,)), rot, np.broadcast_to(s, rot.shape[:-1] + (3,))
    )


def clip_motion(
    asset: RiggedAsset, frames: int, rng: np.random.Generator, fps: float = 30.0, name: str | None = None
) -> tuple[np.ndarray, str] | None:
    """((T, J, 4, 4) local transforms, clip name): the clip ``name`` or one of the asset's clips
    drawn by ``rng``, resampled to ``fps`` (rotations slerped, the rest linear), played forwards and backwards (a
    loop of a clip that is not a cycle would jump) from a random time for ``frames``, the root
    joints at their rest translation (so the animal stays where the camera orbits); None without a
    clip of two or more frames."""
    names = sorted(n for n, c in asset.clips.items() if c.num_frames > 1)
    if not names:
        return None
    if name is not None and name not in names:
        raise UsageError(
            f"{asset.name} has no clip {name!r} of two or more frames",
            hint=f"its clips: {', '.join(names)}" if names else "it has no clips: use --motion random",
        )
    clip = asset.clips[name if name is not None else names[int(rng.integers(len(names)))]]
    period = 2.0 * clip.duration
    t = (float(rng.uniform(0, clip.duration)) + np.arange(frames) / fps) % period
    x = np.where(t > clip.duration, period - t, t) * clip.fps
    i0 = np.minimum(np.floor(x).astype(int), clip.num_frames - 2)
    a = (x - i0)[:, None]  # (T, 1)
    rot = quat_slerp(clip.rotations[i0], clip.rotations[i0 + 1], a)
    trans, scale = (v[i0] + (v[i0 + 1] - v[i0]) * a[..., None] for v in (clip.translations, clip.scales))
    roots = np.asarray(asset.parents) < 0
    trans[:, roots] = asset.rest_trs()[0][roots]
    return compose_trs(trans, quat_normalize(rot), scale), clip.name


MOTIONS = ("random", "clips")


def turn_in_world(points: np.ndarray, degrees: np.ndarray, pivot: np.ndarray) -> np.ndarray:
    """(T, N, 3) ``points`` (T, N, 3) turned about the vertical (+Y) through ``pivot`` (3,) by
    frame t's ``degrees[t]``: the animal's heading in the world."""
    half = np.radians(np.asarray(degrees, np.float64)) / 2
    zero = np.zeros_like(half)
    R = quat_to_matrix(np.stack([np.cos(half), zero, np.sin(half), zero], -1))
    p = np.asarray(points, np.float64) - pivot
    return (np.einsum("tij,tnj->tni", R, p) + pivot).astype(np.asarray(points).dtype)


def camera_path(frames: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Azimuth and elevation (T,) in degrees: the azimuth moves 15-22.5 degrees every 12 frames."""
    az0 = rng.uniform(0, 360)
    keys = np.arange(0, frames + KEY_EVERY, KEY_EVERY)
    steps = rng.uniform(15.0, 22.5, len(keys)) * rng.choice([-1.0, 1.0])
    key_az = az0 + np.concatenate(([0.0], np.cumsum(steps[:-1])))
    az = np.interp(np.arange(frames), keys, key_az)
    el = np.full(frames, rng.uniform(5.0, 25.0))
    return az, el


def _background(h: int, w: int, rng: np.random.Generator) -> np.ndarray:
    c0, c1 = rng.uniform(0.1, 0.9, 3), rng.uniform(0.1, 0.9, 3)
    t = np.linspace(0, 1, h)[:, None, None]
    img = c0 * (1 - t) + c1 * t
    img = np.broadcast_to(img, (h, w, 3)) + rng.normal(0, 0.03, (h, w, 3))
    return (np.clip(img, 0, 1) * 255).astype(np.uint8)


def shade_frames(
    asset: RiggedAsset,
    verts: np.ndarray,
    cams: list,
    light: np.ndarray,
    ambient: float,
    bg: np.ndarray,
    batch: int = 8,
    coat: Coat | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Flat-shaded frames (T, H, W, 3) uint8 over ``bg`` and masks (T, H, W) from per-frame cameras;
    the albedo is each face's mean vertex colour, or ``coat``'s at every pixel (`appearance`)."""
    from ..render.camera import Camera
    from ..render.raster import rasterize

    T = len(verts)
    H, W = cams[0].height, cams[0].width
    faces = torch.as_tensor(asset.faces, dtype=torch.long)
    if asset.vertex_colors is not None:
        albedo = asset.vertex_colors[asset.faces].mean(1)
    else:
        albedo = np.tile([0.72, 0.68, 0.62], (asset.num_faces, 1))
    rgb = np.zeros((T, H, W, 3), np.uint8)
    masks = np.zeros((T, H, W), bool)
    for s in range(0, T, batch):
        idx = range(s, min(s + batch, T))
        cam = Camera(
            torch.cat([cams[i].intrinsics for i in idx]),
            torch.cat([cams[i].rotation for i in idx]),
            torch.cat([cams[i].translation for i in idx]),
            H,
            W,
        )
        v = torch.as_tensor(verts[s : s + len(idx)])
        with torch.no_grad():
            frags = rasterize(v, faces, cam)
        tri = verts[s : s + len(idx)][:, asset.faces]  # (B, F, 3, 3)
        n = np.cross(tri[:, :, 1] - tri[:, :, 0], tri[:, :, 2] - tri[:, :, 0])
        n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-12)
        centres = cam.centers()[0].numpy()  # (B, 3)
        view = tri.mean(2) - centres[:, None]
        n = np.where((n * view).sum(-1, keepdims=True) > 0, -n, n)  # two-sided
        light_f = ambient + (1 - ambient) * np.clip(n @ light, 0, 1)  # (B, F)
        shade = albedo[None] * light_f[..., None]
        shade = (np.clip(shade, 0, 1) ** (1 / 2.2) * 255).astype(np.uint8)
        fid = frags.face_ids.numpy()
        m = fid >= 0
        for b, i in enumerate(idx):
            img = (bg[i] if bg.ndim == 4 else bg).copy()
            if coat is None:
                img[m[b]] = shade[b][fid[b][m[b]]]
            else:
                f = fid[b][m[b]]
                lit = coat.albedo(asset.faces, f, frags.bary[b].numpy()[m[b]]) * light_f[b][f][:, None]
                img[m[b]] = (np.clip(lit, 0, 1) ** (1 / 2.2) * 255).astype(np.uint8)
            rgb[i], masks[i] = img, m[b]
    return rgb, masks


def make_video(
    asset: RiggedAsset,
    out_dir: Path,
    frames: int = 60,
    size: int = 320,
    seed: int = 0,
    fps: float = 30.0,
    motion: str = "random",
    clip: str | None = None,
    appearance: str = "flat",
    fov: float = 40.0,
    background: str = "still",
    turn: float = 0.0,
) -> Path:
    """Render one test video of ``asset`` into ``out_dir/<asset.name>/`` (module docstring);
    ``fov``: the camera's vertical field of view in degrees (the held-out cameras' too);
    ``clip`` names the clip a ``motion="clips"`` video plays (default: one drawn at random);
    ``appearance`` ``textured``: a coat and a scene that a colour bake can be judged on
    (`zooctl.benchdata.appearance`), and the held-out cameras' frames. ``background``: ``still``,
    one image fixed in the frame (a gradient, or the natural scene when textured), as if the
    animal turned on a stand before a backdrop; ``world``, a distant natural scene fixed in the
    world (`world_backgrounds`), which moves in the frame as the camera orbits, as a real
    background does. ``turn``: degrees the animal turns in the world over the clip (module
    docstring; 0: none)."""
    from ..io.video import write_mp4
    from ..render.camera import Camera
    from ..render.preview import fit_camera, orbit_camera
    from ..render.raster import RasterFlow

    if frames < 1 or size < 16:
        raise UsageError("--frames must be >= 1 and --size >= 16")
    if not 5.0 <= fov <= 120.0:
        raise UsageError(f"--fov {fov:g} is not a field of view between 5 and 120 degrees")
    if motion not in MOTIONS:
        raise UsageError(f"--motion {motion!r} is not one of {', '.join(MOTIONS)}")
    if appearance not in APPEARANCES:
        raise UsageError(f"--appearance {appearance!r} is not one of {', '.join(APPEARANCES)}")
    if background not in BACKGROUNDS:
        raise UsageError(f"--background {background!r} is not one of {', '.join(BACKGROUNDS)}")
    if not (math.isfinite(turn) and 0.0 <= turn <= 720.0):
        raise UsageError(f"--turn {turn:g} is not an angle between 0 and 720 degrees")
    rng = np.random.default_rng([seed, sum(asset.name.encode())])
    # 12 more frames than shown: the last one is a held-out novel pose for the re-animation metric.
    played = clip_motion(asset, frames + KEY_EVERY, rng, fps, clip) if motion == "clips" else None
    local, clip_name = played if played is not None else (random_motion(asset, frames + KEY_EVERY, rng), None)
    mats = asset.skinning_matrices(local)  # (T + 12, J, 4, 4)
    from ..asset import lbs

    allv = lbs(asset.vertices, asset.skin_joints, asset.skin_weights, mats).astype(np.float32)
    joints = asset.joint_transforms(local[:frames])[..., :3, 3].astype(np.float32)
    signed = 0.0
    if turn > 0:  # drawn apart: a video without a turn keeps its draws
        signed = turn * float(np.random.default_rng([seed, sum(asset.name.encode()), 3]).choice([-1.0, 1.0]))
        heading = signed * np.arange(len(allv)) / max(frames - 1, 1)  # on past the last frame
        pivot = 0.5 * (allv[0].min(0) + allv[0].max(0))
        allv = turn_in_world(allv, heading, pivot)
        joints = turn_in_world(joints, heading[:frames], pivot)
    verts, novel = allv[:frames], allv[-1]  # (T, V, 3), (V, 3)
    az, el = camera_path(frames, rng)
    lo, hi = verts.reshape(-1, 3).min(0), verts.reshape(-1, 3).max(0)
    centre = 0.5 * (lo + hi)
    ref = fit_camera(
        verts.reshape(-1, 3), size, size, azimuth=float(az[0]), elevation=float(el[0]), fov_y=fov, margin=1.1
    )
    dist = float(np.linalg.norm(ref.centers()[0][0].numpy() - centre))

    def orbit(da: float, de: float) -> list:
        out = []
        for i in range(frames):
            a, e = math.radians(az[i] + da), math.radians(min(el[i] + de, 85.0))
            eye = centre + dist * np.array(
                [math.cos(e) * math.cos(a), math.sin(e), -math.cos(e) * math.sin(a)]
            )
            out.append(orbit_camera(eye, centre, size, size, fov))
        return out

    cams = orbit(0.0, 0.0)
    K = cams[0].intrinsics[0].numpy().astype(np.float64)
    Rs = np.stack([c.rotation[0].numpy() for c in cams]).astype(np.float64)
    ts = np.stack([c.translation[0].numpy() for c in cams]).astype(np.float64)
    light = rng.normal(size=3)
    light[1] = abs(light[1]) + 0.5
    bg = _background(size, size, rng)
    faces_t = torch.as_tensor(asset.faces, dtype=torch.long)
    ambient = float(rng.uniform(0.25, 0.5))
    coat = None
    if appearance == "textured":  # drawn apart: a flat video's draws stay what they were
        look = np.random.default_rng([seed, sum(asset.name.encode()), 1])
        coat, bg = Coat(asset, look), natural_background(size, size, look)
    if background == "world":  # drawn apart too: a still video's draws stay what they were
        bg = world_backgrounds(
            np.random.default_rng([seed, sum(asset.name.encode()), 2]), K, Rs, (size, size)
        )
    rgb, masks = shade_frames(asset, verts, cams, light / np.linalg.norm(light), ambient, bg, coat=coat)
    views = [orbit(da, de) for da, de in NOVEL_VIEWS]
    extra = {}
    if coat is None:
        view_masks = np.stack([shade_frames(asset, verts, c, light, 0.5, bg)[1] for c in views])
    else:  # the same light: a surface point's colour is the same from every camera
        black = np.zeros_like(bg)
        shot = [
            shade_frames(asset, verts, c, light / np.linalg.norm(light), ambient, black, coat=coat)
            for c in views
        ]
        view_masks = np.stack([m for _, m in shot])
        extra["gt_view_frames"] = np.stack([f for f, _ in shot])
    view_R = np.stack([[c.rotation[0].numpy() for c in v] for v in views]).astype(np.float64)
    view_t = np.stack([[c.translation[0].numpy() for c in v] for v in views]).astype(np.float64)
    flow = np.zeros((max(frames - 1, 0), size, size, 2), np.float16)
    valid = np.zeros((max(frames - 1, 0), size, size), bool)
    fr = RasterFlow()
    B = 8
    with torch.no_grad():
        for s0 in range(0, frames - 1, B):
            idx = list(range(s0, min(s0 + B, frames - 1)))
            c0 = Camera(
                torch.cat([cams[i].intrinsics for i in idx]),
                torch.cat([cams[i].rotation for i in idx]),
                torch.cat([cams[i].translation for i in idx]),
                size,
                size,
            )
            c1 = Camera(
                torch.cat([cams[i + 1].intrinsics for i in idx]),
                torch.cat([cams[i + 1].rotation for i in idx]),
                torch.cat([cams[i + 1].translation for i in idx]),
                size,
                size,
            )
            out = fr(
                torch.as_tensor(verts[idx]), faces_t, c0, torch.as_tensor(verts[[i + 1 for i in idx]]), c1
            )
            flow[idx] = out["flow"].numpy().astype(np.float16)
            valid[idx] = out["mask"].numpy()
    dest = Path(out_dir) / asset.name
    dest.mkdir(parents=True, exist_ok=True)
    buf = io.BytesIO()
    np.savez_compressed(
        buf,
        frames=rgb,
        masks=masks,
        flow=flow,
        flow_valid=valid,
        intrinsics=K,
        gt_vertices=verts,
        gt_novel_vertices=novel,
        gt_faces=asset.faces.astype(np.int32),
        gt_joints=joints,
        gt_parents=asset.parents.astype(np.int32),
        gt_skin_joints=asset.skin_joints,
        gt_skin_weights=asset.skin_weights,
        gt_cam_rotation=Rs,
        gt_cam_translation=ts,
        gt_view_masks=view_masks,
        gt_view_rotation=view_R,
        gt_view_translation=view_t,
        **extra,
    )
    write_bytes_atomic(dest / "video.npz", buf.getvalue())
    write_json_atomic(
        dest / "meta.json",
        {
            "name": asset.name,
            "frames": frames,
            "size": size,
            "fps": fps,
            "seed": seed,
            "fov": fov,
            "asset": asset.name,
            **({"body_plan": plan} if (plan := plan_label(asset.name, asset.meta)) else {}),
            "motion": "clips" if clip_name else "random",
            "clip": clip_name,
            **({"appearance": appearance} if coat is not None else {}),
            **({"background": background} if background != "still" else {}),
            **({"turn": signed} if signed else {}),
        },
    )
    write_mp4(dest / "video.mp4", rgb, fps)
    return dest
