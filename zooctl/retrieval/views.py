"""Render an asset's retrieval views: random articulations, cameras, lighting and backgrounds.

As CASA pre-renders its asset bank, every asset gets V views (default `DEFAULT_VIEWS` at
`DEFAULT_SIZE` px). Each view:

- **pose**: a frame of one of the asset's clips (the rest pose when it has none), with every
  non-root joint's local rotation perturbed by a random rotation of at most `MAX_JOINT_DEG`
  degrees (normal angle, sigma `JOINT_SIGMA_DEG`) so that poses the artist did not key appear too;
- **camera**: azimuth uniform all around, elevation in [-10, 45] degrees, vertical field of view
  in [25, 55] degrees, framing the posed mesh;
- **light**: a random direction on the camera's side, random ambient term and albedo gain;
- **background**: a random flat colour, vertical gradient or low-frequency noise texture, so no
  embedder learns "plain grey means bank asset".

The render is cropped to a square around the silhouette (`zooctl.retrieval.crop`), exactly as query
frames are. Everything is drawn from one seeded generator: the same asset and seed give the same views.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .crop import square_crop

DEFAULT_VIEWS = 24
DEFAULT_SIZE = 224
JOINT_SIGMA_DEG = 8.0
MAX_JOINT_DEG = 20.0
RENDER_SCALE = 1.0  # render larger than the crop: the animal fills only part of the framed sphere


@dataclass
class ViewSet:
    """V rendered views of one asset.

    images (V, S, S, 3) uint8 RGB crops; masks (V, S, S) bool silhouettes of the same crops;
    params: per-view arrays (V,) ``clip`` (index into ``clip_names``, -1: rest pose), ``frame``,
    ``azimuth``, ``elevation``, ``fov`` (degrees), ``ambient``, and ``light`` (V, 3).
    """

    images: np.ndarray
    masks: np.ndarray
    params: dict[str, np.ndarray] = field(default_factory=dict)
    clip_names: list[str] = field(default_factory=list)
    seed: int = 0

    def __len__(self) -> int:
        return int(self.images.shape[0])


def random_rotations(rng: np.random.Generator, n: int, sigma_deg: float, max_deg: float) -> np.ndarray:
    """(n, 3, 3) rotations about uniformly random axes by |N(0, sigma)| degrees clipped at max_deg."""
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    ang = np.radians(np.minimum(np.abs(rng.normal(0, sigma_deg, size=n)), max_deg))
    K = np.zeros((n, 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    K = K - K.transpose(0, 2, 1)
    s, c = np.sin(ang)[:, None, None], np.cos(ang)[:, None, None]
    return np.eye(3) + s * K + (1 - c) * (K @ K)


def sample_poses(
    asset, rng: np.random.Generator, n: int, sigma_deg: float = JOINT_SIGMA_DEG
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """n random articulations of ``asset``: local transforms (n, J, 4, 4), clip index (n,), frame (n,)."""
    clips = list(asset.clips.values())
    J = asset.num_joints
    local = np.empty((n, J, 4, 4))
    clip_idx = np.full(n, -1, dtype=np.int32)
    frames = np.zeros(n, dtype=np.int32)
    for i in range(n):
        if clips:
            ci = int(rng.integers(len(clips)))
            f = int(rng.integers(clips[ci].num_frames))
            clip_idx[i], frames[i] = ci, f
            local[i] = clips[ci].local_matrices(f)
        else:
            local[i] = asset.rest_local
    if sigma_deg > 0:
        movable = np.flatnonzero(asset.parents >= 0)
        R = random_rotations(rng, n * len(movable), sigma_deg, MAX_JOINT_DEG).reshape(n, len(movable), 3, 3)
        local[:, movable, :3, :3] = local[:, movable, :3, :3] @ R
    return local, clip_idx, frames


def random_background(rng: np.random.Generator, size: int) -> np.ndarray:
    """(size, size, 3) float linear RGB background: flat, gradient or low-frequency noise."""
    import cv2

    kind = int(rng.integers(3))
    c0, c1 = rng.uniform(0.05, 0.95, 3), rng.uniform(0.05, 0.95, 3)
    if kind == 0:
        bg = np.broadcast_to(c0, (size, size, 3))
    elif kind == 1:
        t = np.linspace(0, 1, size)[:, None, None]
        bg = c0 * (1 - t) + c1 * t
        bg = np.broadcast_to(bg, (size, size, 3))
    else:
        cells = int(rng.integers(3, 9))
        noise = rng.uniform(0, 1, (cells, cells, 1)).astype(np.float32)
        t = cv2.resize(noise, (size, size), interpolation=cv2.INTER_CUBIC).clip(0, 1)[..., None]
        bg = c0 * (1 - t) + c1 * t
    return np.ascontiguousarray(bg, dtype=np.float32) ** 2.2


def light_direction(rng: np.random.Generator, rotation: np.ndarray) -> np.ndarray:
    """A random unit light direction (world, (3,)) from the side of a camera with world-to-camera ``rotation``."""
    d = rng.normal(size=3)
    d[2] = -abs(d[2]) - 0.3  # towards the camera (camera looks down +Z)
    d[1] = -abs(d[1])  # from above (image +Y is down)
    d /= np.linalg.norm(d)
    return rotation.T @ d


def shade_frames(
    posed: np.ndarray,
    faces: np.ndarray,
    colors: np.ndarray,
    cameras: list,
    lights: np.ndarray,
    ambient: np.ndarray,
    gain: np.ndarray,
    backgrounds: list[np.ndarray],
    device: str = "cpu",
) -> tuple[np.ndarray, np.ndarray]:
    """Render N posed copies of one mesh, each with its own camera, light and background.

    posed (N, V, 3); faces (F, 3); colors (V, 3) linear albedo; cameras: N single `Camera`s of one
    size R x R; lights (N, 3) world directions; ambient, gain (N,); backgrounds: N (R, R, 3) linear.
    Returns RGB (N, R, R, 3) uint8 (display gamma) and silhouettes (N, R, R) bool.
    """
    import torch  # here, not at module level: `bank search` imports this module and rarely renders

    from ..render.camera import Camera
    from ..render.preview import surface_at, vertex_normals, zbuffer_mesh

    dev = torch.device(device)
    f = torch.as_tensor(faces, dtype=torch.long, device=dev)
    verts = torch.as_tensor(np.asarray(posed, np.float32), device=dev)
    normals = vertex_normals(verts, f)
    col = torch.as_tensor(np.asarray(colors, np.float32), device=dev)
    cam = Camera(
        torch.cat([c.intrinsics for c in cameras]).to(dev),
        torch.cat([c.rotation for c in cameras]).to(dev),
        torch.cat([c.translation for c in cameras]).to(dev),
        cameras[0].height,
        cameras[0].width,
        cameras[0].near,
    )
    xy, z = cam.project(verts)
    face_ids, bary = zbuffer_mesh(xy, z, f, cam.height, cam.width, cam.near)  # one pass for all N
    img = torch.as_tensor(np.stack(backgrounds), dtype=torch.float32, device=dev).clone()
    hit = face_ids >= 0
    if bool(hit.any()):
        b, n, albedo = surface_at(verts, normals, f, col, cam.centers()[0], face_ids, bary)
        gain_t = torch.as_tensor(np.asarray(gain, np.float32), device=dev)[b, None]
        amb = torch.as_tensor(np.asarray(ambient, np.float32), device=dev)[b, None]
        light = torch.as_tensor(np.asarray(lights, np.float32), device=dev)[b]
        albedo = albedo * gain_t
        lam = (n * light).sum(-1, keepdim=True).clamp(min=0)
        img[hit] = albedo * (amb + (1 - amb) * lam)
    rgb = (img.clamp(0, 1) ** (1 / 2.2) * 255 + 0.5).to(torch.uint8).cpu().numpy()
    return rgb, hit.cpu().numpy()


def asset_colors(asset) -> np.ndarray:
    """(V, 3) linear albedo: the asset's vertex colours, else a neutral grey."""
    if asset.vertex_colors is not None:
        return np.asarray(asset.vertex_colors, np.float32)
    return np.full((asset.num_vertices, 3), 0.6, np.float32)


def render_views(
    asset,
    n_views: int = DEFAULT_VIEWS,
    size: int = DEFAULT_SIZE,
    seed: int = 0,
    device: str = "cpu",
    joint_sigma_deg: float = JOINT_SIGMA_DEG,
) -> ViewSet:
    """Render ``n_views`` random views of a `RiggedAsset`. See the module docstring."""
    from ..asset import lbs
    from ..errors import UsageError
    from ..render.preview import fit_camera

    if n_views < 1:
        raise UsageError(f"--views {n_views} must be at least 1")
    if not 32 <= size <= 1024:
        raise UsageError(f"view size {size} is out of range", hint="use 32 to 1024 pixels (default 224)")
    rng = np.random.default_rng(seed)
    local, clip_idx, frames = sample_poses(asset, rng, n_views, joint_sigma_deg)
    posed = lbs(asset.vertices, asset.skin_joints, asset.skin_weights, asset.skinning_matrices(local)).astype(
        np.float32
    )
    R = int(round(size * RENDER_SCALE))
    az = rng.uniform(0, 360, n_views)
    el = rng.uniform(-10, 45, n_views)
    fov = rng.uniform(25, 55, n_views)
    ambient = rng.uniform(0.2, 0.5, n_views)
    gain = rng.uniform(0.75, 1.25, n_views)
    cams = [fit_camera(posed[i], R, R, az[i], el[i], fov[i], margin=1.02) for i in range(n_views)]
    lights = np.stack([light_direction(rng, c.rotation[0].numpy().astype(np.float64)) for c in cams])
    backgrounds = [random_background(rng, R) for _ in range(n_views)]
    rgb, sil = shade_frames(
        posed, asset.faces, asset_colors(asset), cams, lights, ambient, gain, backgrounds, device
    )
    images = np.empty((n_views, size, size, 3), np.uint8)
    masks = np.empty((n_views, size, size), bool)
    for i in range(n_views):
        crop = square_crop(rgb[i], sil[i], size)
        if crop is None:  # the mesh fell outside the frame (degenerate pose): keep the full render
            import cv2

            crop = (
                cv2.resize(rgb[i], (size, size), interpolation=cv2.INTER_AREA),
                np.zeros((size, size), bool),
            )
        images[i], masks[i] = crop
    params = {
        "clip": clip_idx,
        "frame": frames,
        "azimuth": az.astype(np.float32),
        "elevation": el.astype(np.float32),
        "fov": fov.astype(np.float32),
        "ambient": ambient.astype(np.float32),
        "light": lights.astype(np.float32),
    }
    return ViewSet(images, masks, params, list(asset.clips), seed)
