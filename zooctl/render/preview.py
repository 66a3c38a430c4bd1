"""A shaded preview renderer on the CPU: z-buffer rasterisation and Lambert shading in PyTorch.

Not differentiable and not for fitting: it draws what an asset looks like, for `bank render`
stills, videos and contact sheets, on any machine (the same code runs with ``device="cuda"``).

Rasterisation: `PreviewRenderer` takes the fit's z-buffer (`zooctl.render.raster.rasterize`: the
C++ kernels on the CPU, the same face ids through PyTorch elsewhere). `zbuffer_mesh`, which the
retrieval views render with, covers every face's screen bounding box by a square tile of
candidate pixels, faces grouped by tile size (1, 2, 4, ... pixels) so one vectorised pass handles
each group; each covered pixel keeps the face with the smallest depth through one
``scatter_reduce(amin)`` of a (depth, face id) key packed into an int64. Shading interpolates
smooth vertex normals and vertex colours with perspective-correct barycentrics; lighting is
two-sided (open meshes look right).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..errors import InputError
from .camera import Camera
from .raster import rasterize

DEFAULT_COLOR = (0.72, 0.68, 0.62)
BACKGROUND_TOP = (0.93, 0.94, 0.96)
BACKGROUND_BOTTOM = (0.78, 0.80, 0.84)
_FACE_BITS = 24  # face ids below 2**24 (16.7 million faces)
_DEPTH_LEVELS = 2**38
_BATCH_PIXELS = 1 << 22  # rendered pixels per rasteriser pass of `PreviewRenderer.render`
_BATCH_FACES = 1 << 21  # and faces (memory: a few (B, F, 3, 3) float arrays per pass)


def vertex_normals(vertices: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """Area-weighted unit vertex normals. vertices (B, V, 3), faces (F, 3) -> (B, V, 3)."""
    tri = vertices[:, faces]  # (B, F, 3, 3)
    fn = torch.cross(tri[:, :, 1] - tri[:, :, 0], tri[:, :, 2] - tri[:, :, 0], dim=-1)
    n = torch.zeros_like(vertices)
    for k in range(3):
        n.index_add_(1, faces[:, k], fn)
    return torch.nn.functional.normalize(n, dim=-1, eps=1e-12)


def fit_camera(
    points: np.ndarray,
    height: int,
    width: int,
    azimuth: float = 30.0,
    elevation: float = 18.0,
    fov_y: float = 30.0,
    margin: float = 1.08,
) -> Camera:
    """A camera that frames all ``points`` (N, 3) (e.g. every vertex of every frame of a clip).

    The camera circles the points' centre: ``azimuth`` degrees around +Y from the +X side towards
    -Z (0: looking at the animal's right side, 90: from its front), ``elevation`` degrees above.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0 or not np.all(np.isfinite(pts)):
        raise InputError("cannot frame an empty or non-finite set of points")
    lo, hi = pts.min(0), pts.max(0)
    center = 0.5 * (lo + hi)
    radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-6)
    az, el = math.radians(azimuth), math.radians(elevation)
    direction = np.array([math.cos(el) * math.cos(az), math.sin(el), -math.cos(el) * math.sin(az)])
    half = math.radians(fov_y) / 2
    half_x = math.atan(math.tan(half) * width / height)
    dist = margin * radius / math.sin(min(half, half_x))
    return orbit_camera(center + direction * dist, center, height, width, fov_y)


def orbit_camera(eye: np.ndarray, target: np.ndarray, height: int, width: int, fov_y: float = 30.0) -> Camera:
    """One pinhole `Camera` at ``eye`` looking at ``target`` with world +Y up in the image.

    Camera axes in the `zooctl.render.camera` (OpenCV) convention: +X image right, +Y image down,
    +Z forward.
    """
    forward = np.asarray(target, float) - np.asarray(eye, float)
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    if np.linalg.norm(right) < 1e-9:  # looking straight up or down
        right = np.array([1.0, 0.0, 0.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    R = np.stack([right, down, forward])  # rows: camera axes in world coordinates
    t = -R @ np.asarray(eye, float)
    f = 0.5 * height / math.tan(math.radians(fov_y) / 2)
    return Camera(
        torch.tensor([[f, f, width / 2.0, height / 2.0]], dtype=torch.float32),
        torch.tensor(R[None], dtype=torch.float32),
        torch.tensor(t[None], dtype=torch.float32),
        height,
        width,
    )


class PreviewRenderer:
    """Renders batches of coloured meshes to RGB images.

    ``render(vertices (B, V, 3) or (V, 3), faces (F, 3), camera, colors (V, 3) or None)`` returns
    uint8 images (B, H, W, 3) (or (H, W, 3) for unbatched vertices). ``supersample`` renders at
    that many times the resolution and box-filters down (anti-aliasing).
    """

    def __init__(
        self,
        device: str | torch.device = "cpu",
        supersample: int = 1,
        light: Sequence[float] = (0.4, 0.8, 0.45),
        ambient: float = 0.35,
    ):
        self.device = torch.device(device)
        self.supersample = max(1, int(supersample))
        self.light = torch.nn.functional.normalize(torch.tensor(light, dtype=torch.float32), dim=0).to(
            self.device
        )
        self.ambient = float(ambient)

    @torch.no_grad()
    def render(
        self,
        vertices: np.ndarray | torch.Tensor,
        faces: np.ndarray | torch.Tensor,
        camera: Camera,
        colors: np.ndarray | torch.Tensor | None = None,
    ) -> np.ndarray:
        verts = torch.as_tensor(
            np.asarray(vertices) if not torch.is_tensor(vertices) else vertices, dtype=torch.float32
        ).to(self.device)
        single = verts.ndim == 2
        if single:
            verts = verts[None]
        if verts.ndim != 3 or verts.shape[-1] != 3:
            raise InputError(f"vertices must be (V, 3) or (B, V, 3), got {tuple(verts.shape)}")
        f = torch.as_tensor(np.asarray(faces) if not torch.is_tensor(faces) else faces, dtype=torch.long).to(
            self.device
        )
        if (
            f.ndim != 2
            or f.shape[1] != 3
            or len(f) == 0
            or int(f.min()) < 0
            or int(f.max()) >= verts.shape[1]
        ):
            raise InputError("faces must be a non-empty (F, 3) array of vertex indices")
        if len(f) >= 2**_FACE_BITS:
            raise InputError(f"too many faces to preview ({len(f)})")
        col = (
            torch.tensor(DEFAULT_COLOR).expand(verts.shape[1], 3)
            if colors is None
            else torch.as_tensor(np.asarray(colors), dtype=torch.float32)
        )
        col = col.to(self.device)
        s = self.supersample
        cam = camera.to(self.device, torch.float32).expand(len(verts))
        if s > 1:
            cam = Camera(
                cam.intrinsics * s, cam.rotation, cam.translation, cam.height * s, cam.width * s, cam.near
            )
        normals = vertex_normals(verts, f)
        # Passes of at most _BATCH_PIXELS rendered pixels and _BATCH_FACES faces: bounded memory.
        step = max(1, min(_BATCH_PIXELS // (cam.height * cam.width), _BATCH_FACES // len(f)))
        parts = []
        for i in range(0, len(verts), step):
            c = Camera(
                cam.intrinsics[i : i + step],
                cam.rotation[i : i + step],
                cam.translation[i : i + step],
                cam.height,
                cam.width,
                cam.near,
            )
            parts.append(self._render_batch(verts[i : i + step], normals[i : i + step], f, col, c))
        img = torch.cat(parts)
        # img: (B, H*s, W*s, 3) linear RGB in [0, 1]
        if s > 1:
            img = torch.nn.functional.avg_pool2d(img.permute(0, 3, 1, 2), s).permute(0, 2, 3, 1)
        out = (img.clamp(0, 1) ** (1 / 2.2) * 255 + 0.5).to(torch.uint8).cpu().numpy()  # linear -> display
        return out[0] if single else out

    def _render_batch(
        self, v: torch.Tensor, n: torch.Tensor, f: torch.Tensor, col: torch.Tensor, cam: Camera
    ) -> torch.Tensor:
        """v, n (B, V, 3) vertices and normals, f (F, 3), col (V, 3), cam a batch of B ->
        linear RGB (B, H, W, 3)."""
        H, W = cam.height, cam.width
        centers = cam.centers()[0]  # (B, 3)
        # The fit's z-buffer: C++ kernels on the CPU (a 320 px frame 2.5 times faster than with
        # `zbuffer_mesh`: BENCHMARKS.md, "Preview renderer"), the same face ids on any device.
        frags = rasterize(v, f, cam)
        face_ids, bary = frags.face_ids, frags.bary
        img = _background(H, W, self.device).expand(len(v), H, W, 3).clone()
        hit = face_ids >= 0
        if not bool(hit.any()):
            return img
        _, normal, albedo = surface_at(v, n, f, col, centers, face_ids, bary)
        diffuse = (normal @ self.light).clamp(min=0)[:, None]
        img[hit] = albedo * (self.ambient + (1 - self.ambient) * diffuse)
        return img


def surface_at(
    v: torch.Tensor,
    n: torch.Tensor,
    f: torch.Tensor,
    col: torch.Tensor,
    centers: torch.Tensor,
    face_ids: torch.Tensor,
    bary: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """What each covered pixel of `zbuffer_mesh`'s (B, H, W) output sees: v, n (B, V, 3) vertices
    and unit normals, f (F, 3), col (V, 3) linear colours, centers (B, 3) camera centres ->
    (image index (P,), unit normal (P, 3) turned towards the camera (two-sided), albedo (P, 3)) for
    the P pixels where ``face_ids >= 0``, in their row-major order."""
    hit = face_ids >= 0
    b = torch.nonzero(hit)[:, 0]
    w = bary[hit][..., None]  # (P, 3, 1) perspective-correct barycentrics
    tri = f[face_ids[hit]]  # (P, 3)
    normal = torch.nn.functional.normalize((n[b[:, None], tri] * w).sum(1), dim=-1, eps=1e-12)
    albedo = (col[tri] * w).sum(1)
    view = torch.nn.functional.normalize(v[b, tri[:, 0]] - centers[b], dim=-1)
    normal = torch.where((normal * view).sum(-1, keepdim=True) > 0, -normal, normal)
    return b, normal, albedo


def zbuffer_mesh(
    xy: torch.Tensor,
    z: torch.Tensor,
    faces: torch.Tensor,
    height: int,
    width: int,
    near: float = 1e-3,
    skip: torch.Tensor | None = None,
    max_candidates: int = 1 << 21,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Z-buffer rasterisation of one mesh, or of a batch of poses of it, for previews (no
    gradients; the differentiable one is `zooctl.render.raster.rasterize`).

    xy (V, 2) or (B, V, 2) pixel positions (pixel (i, j) is centred at (j + 0.5, i + 0.5)), z
    (V,) or (B, V) camera depths, faces (F, 3); ``skip`` (F,) or (B, F) bool marks faces not to
    draw (culled back faces). Returns face ids (H, W) or (B, H, W) int64 (-1: background) and
    perspective-correct barycentric weights (H, W, 3) or (B, H, W, 3). Faces with a vertex nearer
    than ``near`` are skipped. A batch is one pass over all its images (each with its own depth
    range), so its result is the same as rendering the images one by one, at a fraction of the
    per-call cost.
    """
    single = xy.ndim == 2
    if single:
        xy, z = xy[None], z[None]
        skip = None if skip is None else skip[None]
    dev = xy.device
    nb, nf = xy.shape[0], faces.shape[0]
    if nf * nb >= 2**_FACE_BITS:  # the packed key holds face ids below 2**_FACE_BITS
        half = max(1, nb // 2)
        parts = [
            zbuffer_mesh(
                xy[s : s + half],
                z[s : s + half],
                faces,
                height,
                width,
                near,
                None if skip is None else skip[s : s + half],
                max_candidates,
            )
            for s in range(0, nb, half)
        ]
        ids, bary = torch.cat([p[0] for p in parts]), torch.cat([p[1] for p in parts])
        return (ids[0], bary[0]) if single else (ids, bary)
    tri = xy[:, faces].reshape(nb * nf, 3, 2)  # faces of image b are b * F ... (b + 1) * F - 1
    tz = z[:, faces].reshape(nb * nf, 3)
    img_of = torch.arange(nb, device=dev).repeat_interleave(nf)  # (B * F,)
    lo = tri.min(1).values
    hi = tri.max(1).values
    x0 = torch.floor(lo[:, 0] - 0.5).clamp(min=0)
    y0 = torch.floor(lo[:, 1] - 0.5).clamp(min=0)
    x1 = torch.ceil(hi[:, 0] - 0.5).clamp(max=width - 1)
    y1 = torch.ceil(hi[:, 1] - 0.5).clamp(max=height - 1)
    area = _edge(tri[:, 0], tri[:, 1], tri[:, 2])
    ok = (tz.min(1).values > near) & (x1 >= x0) & (y1 >= y0) & (area.abs() > 1e-12)
    if skip is not None:
        ok &= ~skip.reshape(-1)
    # Barycentric weight i of pixel centre p is the affine function A_i p.x + B_i p.y + C_i.
    a, b = tri, tri.roll(-1, dims=1)  # edges (v1, v2), (v2, v0), (v0, v1) opposite v0, v1, v2
    a, b = a.roll(-1, dims=1), b.roll(-1, dims=1)
    inv = 1.0 / torch.where(area.abs() > 1e-12, area, torch.ones_like(area))
    A = -(b[..., 1] - a[..., 1]) * inv[:, None]
    B = (b[..., 0] - a[..., 0]) * inv[:, None]
    C = ((b[..., 1] - a[..., 1]) * a[..., 0] - (b[..., 0] - a[..., 0]) * a[..., 1]) * inv[:, None]
    inv_z = 1.0 / tz.clamp(min=1e-12)
    npix = height * width
    zbuf = torch.full((nb * npix,), torch.iinfo(torch.int64).max, dtype=torch.int64, device=dev)
    if bool(ok.any()):
        # Depth quantised per image over the depth range of its drawn faces.
        big = torch.finfo(tz.dtype).max
        fmin = torch.where(ok, tz.min(1).values, torch.full_like(ok, big, dtype=tz.dtype))
        fmax = torch.where(ok, tz.max(1).values, torch.full_like(ok, -big, dtype=tz.dtype))
        zmin = fmin.reshape(nb, nf).min(1).values
        zmax = fmax.reshape(nb, nf).max(1).values
        scale = ((_DEPTH_LEVELS - 1) / (zmax.double() - zmin.double()).clamp(min=1e-12)).to(tz.dtype)
        zmin_f, scale_f = zmin[img_of], scale[img_of]
        # Faces grouped by the power-of-two size of their box's width and height.
        bw = _ceil_pow2(x1 - x0 + 1)
        bh = _ceil_pow2(y1 - y0 + 1)
        key = torch.where(ok, bw * 4096 + bh, torch.zeros_like(bw))
        for k in torch.unique(key[ok]).tolist():
            W_, H_ = int(k) // 4096, int(k) % 4096
            sel = torch.nonzero(key == k).squeeze(1)
            oy, ox = torch.meshgrid(torch.arange(H_, device=dev), torch.arange(W_, device=dev), indexing="ij")
            ox, oy = ox.reshape(-1).float(), oy.reshape(-1).float()
            chunk = max(1, max_candidates // (W_ * H_))
            for start in range(0, len(sel), chunk):
                fi = sel[start : start + chunk]
                px = x0[fi, None] + ox  # (Fc, P)
                py = y0[fi, None] + oy
                cx, cy = px + 0.5, py + 0.5
                w0 = A[fi, 0, None] * cx + B[fi, 0, None] * cy + C[fi, 0, None]
                w1 = A[fi, 1, None] * cx + B[fi, 1, None] * cy + C[fi, 1, None]
                w2 = 1.0 - w0 - w1
                inside = (
                    (px <= x1[fi, None])
                    & (py <= y1[fi, None])
                    & (w0 >= -1e-6)
                    & (w1 >= -1e-6)
                    & (w2 >= -1e-6)
                )
                r, c = torch.nonzero(inside, as_tuple=True)
                if len(r) == 0:
                    continue
                f = fi[r]
                iz = w0[r, c] * inv_z[f, 0] + w1[r, c] * inv_z[f, 1] + w2[r, c] * inv_z[f, 2]
                depth = 1.0 / iz.clamp(min=1e-12)
                q = ((depth - zmin_f[f]) * scale_f[f]).clamp(0, _DEPTH_LEVELS - 1).to(torch.int64)
                pix = img_of[f] * npix + (py[r, c] * width + px[r, c]).to(torch.int64)
                zbuf.scatter_reduce_(0, pix, (q << _FACE_BITS) | f, reduce="amin")
    hit = zbuf != torch.iinfo(torch.int64).max
    face_ids = torch.where(hit, zbuf & ((1 << _FACE_BITS) - 1), torch.full_like(zbuf, -1))
    bary = torch.zeros(nb * npix, 3, device=dev)
    idx = torch.nonzero(hit).squeeze(1)
    if len(idx):
        fi = face_ids[idx]
        local = idx % npix
        cx = (local % width).float() + 0.5
        cy = (local // width).float() + 0.5
        w = A[fi] * cx[:, None] + B[fi] * cy[:, None] + C[fi]
        w = w * inv_z[fi]  # screen-space -> perspective-correct
        bary[idx] = w / w.sum(-1, keepdim=True)
        face_ids[idx] = fi - (idx // npix) * nf  # ids within each image's mesh
    face_ids, bary = face_ids.reshape(nb, height, width), bary.reshape(nb, height, width, 3)
    return (face_ids[0], bary[0]) if single else (face_ids, bary)


def _ceil_pow2(n: torch.Tensor) -> torch.Tensor:
    """Smallest power of two >= n (n >= 1), as int64."""
    n = n.clamp(min=1).to(torch.int64)
    return torch.pow(2, torch.ceil(torch.log2(n.double())).to(torch.int64))


def _edge(a: torch.Tensor, b: torch.Tensor, c: torch.Tensor) -> torch.Tensor:
    """Twice the signed area of triangles (a, b, c); points (..., 2)."""
    return (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (
        c[..., 0] - a[..., 0]
    )


def _background(height: int, width: int, device: torch.device) -> torch.Tensor:
    t = torch.linspace(0, 1, height, device=device)[:, None, None]
    top = torch.tensor(BACKGROUND_TOP, device=device) ** 2.2
    bottom = torch.tensor(BACKGROUND_BOTTOM, device=device) ** 2.2
    return (top * (1 - t) + bottom * t).expand(height, width, 3).clone()


# -- assets -----------------------------------------------------------------------------------
def render_asset(asset, *args: Any, **kwargs: Any) -> np.ndarray:
    """Render an asset (`zooctl.asset.RiggedAsset`) posed at frames of a clip, or its rest pose:
    uint8 (T, size, width or size, 3), `render_asset_frames` (same arguments) gathered."""
    return np.stack(list(render_asset_frames(asset, *args, **kwargs)))


def render_asset_frames(
    asset,
    clip: str | None = None,
    frames: Iterable[int] | None = None,
    size: int = 256,
    width: int | None = None,
    azimuth: float = 30.0,
    elevation: float = 18.0,
    supersample: int = 2,
    device: str = "cpu",
    batch: int | None = None,
) -> Iterator[np.ndarray]:
    """`render_asset`'s frames (size, width or size, 3) uint8 one at a time, posed and rendered
    ``batch`` frames at once (default: as many as 32 MB of posed vertices hold), so a long clip is
    never held whole. The camera is fixed for the whole clip, framing every vertex of every
    rendered frame (a first pass over the poses' bounds), so motion is visible."""
    if clip is None:
        idx = None
    else:
        if clip not in asset.clips:
            raise InputError(
                f"asset {asset.name!r} has no clip {clip!r}",
                hint=f"clips: {', '.join(asset.clips) or 'none'}",
            )
        idx = (
            np.arange(asset.clips[clip].num_frames) if frames is None else np.asarray(list(frames), dtype=int)
        )
        if len(idx) == 0:
            raise InputError("no frames to render")
    step = batch or max(1, (32 << 20) // (24 * asset.num_vertices))
    parts = [None] if idx is None else [idx[s : s + step] for s in range(0, len(idx), step)]

    def posed(part: np.ndarray | None) -> np.ndarray:
        return asset.pose(None)[None] if part is None else asset.pose(clip, part)

    # One batch (a still, a short clip) is posed once; longer clips twice, to keep one batch in memory.
    kept = [posed(parts[0])] if len(parts) == 1 else None
    poses = kept or map(posed, parts)
    corners = np.concatenate([np.stack([p.min(1), p.max(1)], 1).reshape(-1, 3) for p in poses])
    cam = fit_camera(corners, size, width or size, azimuth, elevation)
    renderer = PreviewRenderer(device=device, supersample=supersample)
    for p in kept or map(posed, parts):
        yield from renderer.render(p, asset.faces, cam, asset.vertex_colors)


def contact_sheet(
    images: Sequence[np.ndarray],
    labels: Sequence[str] | None = None,
    columns: int | None = None,
    pad: int = 6,
    label_height: int = 18,
) -> np.ndarray:
    """Tile equally sized (H, W, 3) uint8 images into one sheet, each with its label underneath."""
    from PIL import Image, ImageDraw

    if not images:
        raise InputError("no images for a contact sheet")
    h, w = images[0].shape[:2]
    if any(im.shape[:2] != (h, w) for im in images):
        raise InputError("contact sheet images must all have the same size")
    n = len(images)
    cols = columns or max(1, math.ceil(math.sqrt(n * 1.3)))
    rows = math.ceil(n / cols)
    lh = label_height if labels else 0
    sheet = Image.new("RGB", (cols * (w + pad) + pad, rows * (h + lh + pad) + pad), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    for i, im in enumerate(images):
        r, c = divmod(i, cols)
        x, y = pad + c * (w + pad), pad + r * (h + lh + pad)
        sheet.paste(Image.fromarray(np.asarray(im, dtype=np.uint8)), (x, y))
        if labels:
            text = str(labels[i])
            tw = draw.textlength(text)
            while tw > w and len(text) > 4:
                text = text[:-2] + "…"
                tw = draw.textlength(text)
            draw.text((x + (w - tw) / 2, y + h + 3), text, fill=(30, 30, 30))
    return np.asarray(sheet)


def save_png(path: str | Path, image: np.ndarray) -> Path:
    """Write an (H, W, 3) uint8 image as PNG, atomically (temporary file, fsync, rename)."""
    import io

    from PIL import Image

    from ..store.fs import write_bytes_atomic

    path = Path(path)
    buf = io.BytesIO()
    Image.fromarray(np.asarray(image, dtype=np.uint8)).save(buf, format="PNG")
    write_bytes_atomic(path, buf.getvalue())
    return path
