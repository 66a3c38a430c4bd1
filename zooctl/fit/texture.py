"""Baking the video's colours onto the fitted character.

A surface sample (a face and barycentrics) is posed with the character's ``fit`` clip and
projected through the fit's camera into every frame. It takes that frame's colour when

- the z-buffer of the posed mesh says it is the nearest surface at its pixel (visibility),
- the pixel is inside the frame's mask,

weighted by the cosine between its normal and the ray to the camera (surface seen edge-on gets
little) and by how far inside the mask the pixel is: the fit's outline only roughly follows the
animal's, so colours at the mask's edge are often background, and full weight starts a fixed
fraction of the mask's size inside it. Colours are averaged in linear RGB.

A sample seen too little (less weight than half a frontal view) is blended with a fill colour:
in a texture, that of a seen texel right beside it when there is one (the rim of a silhouette,
seen edge-on, continues the surface seen next to it), else that of its mirror image across the symmetry plane
when the mesh is symmetric and the mirror image was seen, else that of the nearest seen sample
(straight-line distance). Both are judged on a
reference shape with the character's vertices: the template's (a fit keeps its topology), whose
symmetry the fit's displacements and stretched bones may have bent, else the character's own.

Where the character has UVs that lie in the unit square without overlapping, the samples are the
texels of a square texture (PNG, sRGB; texels off every triangle take the nearest baked colour so
that filtering does not bleed), exported as ``baseColorTexture`` / ``UsdUVTexture``. A character
without such UVs (the bank's templates have none) gets a generated atlas first (`uv_atlas`). Only
where none can be made are the samples the corners of every face, averaged into vertex colours
(``COLOR_0`` / ``displayColor``).
"""

from __future__ import annotations

import dataclasses
import io
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from ..asset import RiggedAsset
from ..errors import InputError

TEXTURE_SIZE = 512
EDGE_FRACTION = 0.03  # of the mask's bounding-box diagonal: where a pixel gets full weight
DEPTH_TOLERANCE = 0.005  # of the posed mesh's size: a sample this far behind the z-buffer is hidden
SEEN_WEIGHT = 0.5  # weight (in frontal views) from which a sample's own colour stands alone
SYMMETRY_RMS = 0.02  # find_symmetry_plane residual below which the mesh counts as symmetric
MIRROR_TOLERANCE = 0.03  # of the mesh's size: how near a seen sample must be to the mirror image
NEAR_TOLERANCE = 0.02  # of the mesh's size: a seen texel this near fills a little-seen one first
_CORNER = 0.6  # barycentric weight of the corner a vertex sample sits nearest to


@dataclass
class Samples:
    """Surface samples: face (S,) long, bary (S, 3) float32; ``texel`` (S,) flat texel index
    (texture bake) or ``vertex`` (S,) the vertex each corner sample belongs to (vertex colours)."""

    face: np.ndarray
    bary: np.ndarray
    texel: np.ndarray | None = None
    vertex: np.ndarray | None = None

    def points(self, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
        """(S, 3) positions of the samples on a mesh with ``vertices`` (V, 3)."""
        tri = vertices[faces[self.face]]  # (S, 3, 3)
        return np.einsum("sk,skc->sc", self.bary.astype(np.float64), tri)


def corner_samples(faces: np.ndarray) -> Samples:
    """One sample per face corner, a little inside the face (edges are where visibility is unsure)."""
    F = len(faces)
    side = (1.0 - _CORNER) / 2
    bary = np.full((F, 3, 3), side, np.float32)
    bary[:, np.arange(3), np.arange(3)] = _CORNER
    return Samples(
        face=np.repeat(np.arange(F), 3), bary=bary.reshape(-1, 3), vertex=faces.reshape(-1).astype(np.int64)
    )


def uv_samples(uvs: np.ndarray | None, faces: np.ndarray, size: int = TEXTURE_SIZE) -> Samples | None:
    """The texels of a ``size`` x ``size`` texture covered by the UV triangles, or None when the
    UVs cannot hold a baked texture: absent, outside the unit square, or overlapping (one texel on
    two places of the surface)."""
    from ..render.camera import Camera
    from ..render.raster import rasterize

    if uvs is None or len(faces) == 0:
        return None
    uv = np.asarray(uvs, np.float64)
    if not np.all(np.isfinite(uv)) or uv.min() < -1e-4 or uv.max() > 1 + 1e-4:
        return None
    tri = uv[faces] * size  # glTF: u right, v down, as image columns and rows
    area = 0.5 * np.abs(
        (tri[:, 1, 0] - tri[:, 0, 0]) * (tri[:, 2, 1] - tri[:, 0, 1])
        - (tri[:, 1, 1] - tri[:, 0, 1]) * (tri[:, 2, 0] - tri[:, 0, 0])
    )
    # The UV layout as a mesh at depth 1 seen by a camera with unit focal length: pixels are texels.
    flat = torch.as_tensor(np.concatenate([uv * size, np.ones((len(uv), 1))], 1)[None], dtype=torch.float32)
    eye = torch.eye(3)[None]
    cam = Camera(torch.tensor([[1.0, 1.0, 0.0, 0.0]]), eye, torch.zeros(1, 3), size, size)
    frags = rasterize(flat, torch.as_tensor(faces, dtype=torch.long), cam)
    covered = frags.mask[0].reshape(-1)
    count = int(covered.sum())
    if count < 64 or area.sum() > 1.1 * count + 0.05 * size * size**0.5:
        return None  # too small to bake into, or overlapping islands
    texel = torch.nonzero(covered).squeeze(1)
    return Samples(
        face=frags.face_ids[0].reshape(-1)[texel].numpy().astype(np.int64),
        bary=frags.bary[0].reshape(-1, 3)[texel].numpy().astype(np.float32),
        texel=texel.numpy().astype(np.int64),
    )


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    c = np.asarray(c, np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(c: np.ndarray) -> np.ndarray:
    c = np.clip(np.asarray(c, np.float64), 0, 1)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)


def edge_weights(masks: np.ndarray) -> np.ndarray:
    """(T, H, W) float32 in [0, 1]: 0 outside each mask, rising to 1 at `EDGE_FRACTION` of the
    mask's bounding-box diagonal inside it."""
    import cv2

    out = np.zeros(masks.shape, np.float32)
    for t, m in enumerate(masks):
        if not m.any():
            continue
        rows, cols = np.nonzero(m.any(1))[0], np.nonzero(m.any(0))[0]
        diag = float(np.hypot(rows[-1] - rows[0] + 1, cols[-1] - cols[0] + 1))
        dist = cv2.distanceTransform(m.astype(np.uint8), cv2.DIST_L2, 3)
        out[t] = np.clip(dist / max(EDGE_FRACTION * diag, 1.0), 0, 1)
    return out


@torch.no_grad()
def observe(
    asset: RiggedAsset,
    camera,
    frames: np.ndarray,
    masks: np.ndarray,
    samples: Samples,
    clip: str = "fit",
    batch: int = 8,
) -> tuple[np.ndarray, np.ndarray]:
    """Weighted sums of the samples' colours over the frames (module docstring): (S, 3) sum of
    weight x linear colour, (S,) sum of weights. ``camera`` is one camera at the frames' size."""
    from ..render.raster import rasterize

    T, H, W = frames.shape[:3]
    faces = torch.as_tensor(asset.faces, dtype=torch.long)
    face = torch.as_tensor(samples.face, dtype=torch.long)
    bary = torch.as_tensor(samples.bary, dtype=torch.float32)
    lut = torch.as_tensor(srgb_to_linear(np.arange(256) / 255.0), dtype=torch.float32)
    S = len(face)
    batch = max(1, min(batch, 2_000_000 // max(S, 1)))  # a few (B, S, 3, 3) arrays stay small
    sum_wc, sum_w = torch.zeros(S, 3, dtype=torch.float64), torch.zeros(S, dtype=torch.float64)
    for s in range(0, T, batch):
        idx = np.arange(s, min(s + batch, T))
        B = len(idx)
        v = torch.as_tensor(asset.pose(clip, idx).astype(np.float32))  # (B, V, 3)
        cam = camera.expand(B)
        frags = rasterize(v, faces, cam)
        tri = v[:, faces]  # (B, F, 3, 3)
        normals = torch.nn.functional.normalize(
            torch.cross(tri[:, :, 1] - tri[:, :, 0], tri[:, :, 2] - tri[:, :, 0], dim=-1), dim=-1, eps=1e-20
        )[:, face]  # (B, S, 3)
        p = torch.einsum("sk,bskc->bsc", bary, tri[:, face])
        centre, _ = cam.centers()
        ray = torch.nn.functional.normalize(centre[:, None] - p, dim=-1, eps=1e-20)
        cos = (normals * ray).sum(-1).abs()  # either winding: occlusion is the z-buffer's business
        xy, z = cam.project(p)
        col, row = xy[..., 0].floor().long(), xy[..., 1].floor().long()
        inside = (col >= 0) & (col < W) & (row >= 0) & (row < H) & (z > cam.near)
        col, row = col.clamp(0, W - 1), row.clamp(0, H - 1)
        b = torch.arange(B)[:, None]
        size = (v.amax(1) - v.amin(1)).norm(dim=-1)  # (B,)
        hit = frags.face_ids[b, row, col] == face[None]
        near = z <= frags.depth[b, row, col] + DEPTH_TOLERANCE * size[:, None]
        visible = inside & frags.mask[b, row, col] & (hit | near)
        edge = torch.as_tensor(edge_weights(masks[idx]))[b, row, col]
        w = torch.where(visible, cos * edge, torch.zeros_like(cos))
        img = lut[torch.as_tensor(frames[idx]).long()].permute(0, 3, 1, 2)  # (B, 3, H, W) linear
        grid = torch.stack((2 * xy[..., 0] / W - 1, 2 * xy[..., 1] / H - 1), -1)[:, :, None]  # (B, S, 1, 2)
        rgb = torch.nn.functional.grid_sample(
            img, grid, mode="nearest", align_corners=False, padding_mode="border"
        )
        rgb = rgb[..., 0].permute(0, 2, 1)  # (B, S, 3)
        sum_wc += (w[..., None] * rgb).sum(0).double()
        sum_w += w.sum(0).double()
    return sum_wc.numpy(), sum_w.numpy()


def fill_unseen(
    points: np.ndarray,
    sum_wc: np.ndarray,
    sum_w: np.ndarray,
    plane: tuple[np.ndarray, float] | None,
    near: float = 0.0,
) -> tuple[np.ndarray, dict[str, float]] | None:
    """(N, 3) linear colours of N samples at rest positions ``points`` from their weighted sums,
    the little-seen ones blended with a fill colour (module docstring); ``plane`` (unit normal,
    offset) of the mesh's symmetry, or None; ``near`` (a fraction of the mesh's size): how near a
    seen sample fills before the mirror image does (0: the mirror image first). None when
    nothing was seen at all."""
    from scipy.spatial import cKDTree

    seen = sum_w >= SEEN_WEIGHT
    if not seen.any():
        seen = sum_w > 0
    if not seen.any():
        return None
    own = sum_wc / np.maximum(sum_w, 1e-12)[:, None]
    out = own.copy()
    weak = ~(sum_w >= SEEN_WEIGHT)
    mirrored = np.zeros(len(points), bool)
    if weak.any():
        tree = cKDTree(points[seen])
        source = own[seen]
        q = points[weak]
        fill = np.zeros_like(q)
        size = float(np.linalg.norm(points.max(0) - points.min(0))) or 1.0
        # Bounded queries: one whose answer is far is the slow kind. A sample right beside seen
        # surface (a silhouette's rim) continues it; farther ones take their mirror image.
        ok = np.zeros(len(q), bool)
        if near > 0:
            dist, j = tree.query(q, distance_upper_bound=near * size)
            ok = np.isfinite(dist)
            fill[ok] = source[j[ok]]
        if plane is not None and not ok.all():
            n, d = plane
            rest = np.nonzero(~ok)[0]
            refl = q[rest] - 2.0 * ((q[rest] @ n) - d)[:, None] * n
            dist, j = tree.query(refl, distance_upper_bound=MIRROR_TOLERANCE * size)
            hit = np.isfinite(dist)
            fill[rest[hit]] = source[j[hit]]
            ok[rest[hit]] = True
            mirrored[np.nonzero(weak)[0][rest[hit]]] = True
        if not ok.all():
            # Nearest within a few percent: the fill of a far hidden patch needs no exact neighbour.
            fill[~ok] = source[tree.query(q[~ok], eps=0.5)[1]]
        w = sum_w[weak][:, None]
        out[weak] = (w * own[weak] + SEEN_WEIGHT * fill) / (w + SEEN_WEIGHT)
    info = {
        "seen": float(np.mean(sum_w >= SEEN_WEIGHT)),
        "glimpsed": float(np.mean((sum_w > 0) & (sum_w < SEEN_WEIGHT))),
        "mirrored": float(np.mean(mirrored)),
    }
    return np.clip(out, 0, 1), info


def symmetry_plane(vertices: np.ndarray) -> tuple[np.ndarray, float] | None:
    """The mesh's mirror plane (unit normal, offset) when it is symmetric enough to copy colours
    across, else None."""
    from ..rig.priors import find_symmetry_plane

    try:
        n, d, rms = find_symmetry_plane(vertices)
    except InputError:
        return None
    return (n, d) if rms <= SYMMETRY_RMS else None


def _png(rgb: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(rgb).save(buf, format="PNG")
    return buf.getvalue()


def texture_image(samples: Samples, colors: np.ndarray, size: int) -> np.ndarray:
    """(size, size, 3) uint8 sRGB: each sample's colour at its texel, the texels off every UV
    triangle the colour of the nearest one on a triangle."""
    from scipy.ndimage import distance_transform_edt

    img = np.zeros((size * size, 3), np.float64)
    img[samples.texel] = colors
    empty = np.ones(size * size, bool)
    empty[samples.texel] = False
    img = img.reshape(size, size, 3)
    idx = distance_transform_edt(empty.reshape(size, size), return_distances=False, return_indices=True)
    img = img[idx[0], idx[1]]
    return (linear_to_srgb(img) * 255 + 0.5).astype(np.uint8)


def bake(
    asset: RiggedAsset,
    camera,
    frames: np.ndarray,
    masks: np.ndarray,
    clip: str = "fit",
    texture_size: int = TEXTURE_SIZE,
    reference: np.ndarray | None = None,
    make_uvs: bool = True,
) -> tuple[RiggedAsset, dict[str, Any]]:
    """``asset`` wearing the colours of ``frames`` (T, H, W, 3) uint8 sRGB inside ``masks``
    (T, H, W) bool, seen through ``camera`` (one camera at the frames' size) with its clip
    ``clip`` (one sample per frame): a UV texture or vertex colours (module docstring);
    ``reference`` (V, 3): the shape symmetry and nearness are judged on (default: the asset's
    bind-pose vertices). Without usable UVs and with ``make_uvs``, the character gets a generated
    atlas first (`zooctl.fit.uv_atlas`: seam vertices split) and a texture is baked into it; vertex
    colours only where no atlas could be made. Returns the new asset (the input one, unchanged,
    when no frame saw it) and what the bake did: mode (``texture``, ``vertex`` or ``none``), where
    the UVs came from (``asset``, ``generated`` or None), the fractions of the surface seen,
    glimpsed and filled from its mirror image, and the seconds it took."""
    original = asset
    t0 = time.perf_counter()
    shape = asset.vertices if reference is None else np.asarray(reference)
    if shape.shape != asset.vertices.shape:
        raise InputError(f"the reference shape has {len(shape)} vertices, the character {asset.num_vertices}")
    shape = shape.astype(np.float64)
    samples = uv_samples(asset.uvs, asset.faces, texture_size)
    uv_source = "asset" if samples is not None else None
    if samples is None and make_uvs:
        from .uv_atlas import with_atlas

        made = with_atlas(asset, texture_size)
        if made is not None:
            samples = uv_samples(made[0].uvs, made[0].faces, texture_size)
            if samples is not None:
                asset, shape, uv_source = made[0], shape[made[1]], "generated"
    mode = "texture" if samples is not None else "vertex"
    if samples is None:
        samples = corner_samples(asset.faces)
    sum_wc, sum_w = observe(asset, camera, frames, masks, samples, clip)
    if mode == "vertex":
        V = asset.num_vertices
        sum_wc = np.stack([np.bincount(samples.vertex, sum_wc[:, c], V) for c in range(3)], 1)
        sum_w = np.bincount(samples.vertex, sum_w, V)
        points = shape
    else:
        points = samples.points(shape, asset.faces)
    # Texels are dense enough that the nearest seen one beside a rim texel is the same surface;
    # a vertex's nearest seen neighbour may be another part (a leg beside the belly).
    near = NEAR_TOLERANCE if mode == "texture" else 0.0
    filled = fill_unseen(points, sum_wc, sum_w, symmetry_plane(shape), near)
    info: dict[str, Any] = {"mode": mode, "frames": int(len(frames)), "uvs": uv_source}
    if filled is None:
        info["mode"], info["uvs"] = "none", None
        info["seconds"] = time.perf_counter() - t0
        return original, info
    colors, stats = filled
    info.update(stats)
    if mode == "vertex":
        out = dataclasses.replace(asset, vertex_colors=colors.astype(np.float32), texture_png=None)
    else:
        png = _png(texture_image(samples, colors, texture_size))
        out = dataclasses.replace(asset, vertex_colors=None, texture_png=png)
        info["texture_size"] = texture_size
    info["seconds"] = time.perf_counter() - t0
    return out.validate(), info
