"""The photometric term: the fitted surface, in learned per-vertex colours, rendered through the
z-buffer rasteriser and compared with the frames (``weights.photometric``; issue 50).

Every pixel the posed mesh covers inside the mask gets the colour interpolated from its face's
vertices with the perspective-correct barycentrics of `zooctl.render.raster.rasterize`. The term is the
mean L1 distance (summed over RGB) of the frame's colour from it, after a per-frame, per-channel
gain: the ratio of the frame's mean to the render's over those pixels, held fixed within a step,
which absorbs exposure and lighting changes. The gradient reaches the surface through the
barycentrics (which point of a face each pixel sees) and the colours themselves, a (V, 3)
parameter of stage 2 started from the frames' colours at the vertices (`initial_colours`).

Every covered pixel must be explained by the surface point the render puts there, so the term
cannot be lowered by vertices crowding onto an evenly coloured part of the animal, as a term on
each vertex's colour across frames can (`bench/photometric.py`, BENCHMARKS.md).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from ..render.camera import Camera
from ..render.raster import rasterize

Tensor = torch.Tensor
VISIBLE_DEPTH = 0.01  # of the posed mesh's size: a vertex this far behind the z-buffer is hidden


def colour_targets(
    frames: Any, box: tuple[int, int, int, int], h: int, w: int, device: str = "cpu"
) -> Tensor:
    """(T, h, w, 3) float32 sRGB in [0, 1]: frames (T, H, W, 3) uint8 (an array or a lazily read
    `FrameArray`) cropped to ``box`` (x0, y0, x1, y1) and resized to the fit resolution."""
    import cv2

    x0, y0, x1, y1 = box
    out = np.empty((len(frames), h, w, 3), np.float32)
    for t in range(len(frames)):
        crop = np.asarray(frames[t])[y0:y1, x0:x1]
        out[t] = cv2.resize(crop, (w, h), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
    return torch.as_tensor(out, device=device)


@torch.no_grad()
def initial_colours(scene, images: Tensor, coverage: Tensor, frames: range, batch: int = 8) -> Tensor:
    """(V, 3) each vertex's mean colour over ``frames`` where it is the nearest surface at its
    pixel inside the mask, as ``scene`` poses it now; the mean of those colours for a vertex never
    seen (of the frames inside the masks when none is). images (T, h, w, 3), coverage (T, h, w)."""
    acc = n = None
    idx_all = torch.as_tensor(list(frames), device=images.device)
    for s in range(0, len(idx_all), batch):
        idx = idx_all[s : s + batch]
        verts = scene.pose(idx).vertices
        B, V, _ = verts.shape
        cam = scene.camera(B)
        frags = rasterize(verts, scene.faces, cam)
        xy, z = cam.project(verts)
        H, W = frags.mask.shape[1:]
        col, row = xy[..., 0].floor().long(), xy[..., 1].floor().long()
        inside = (col >= 0) & (col < W) & (row >= 0) & (row < H)
        col, row = col.clamp(0, W - 1), row.clamp(0, H - 1)
        b = torch.arange(B, device=verts.device)[:, None]
        size = (verts.amax(1) - verts.amin(1)).norm(dim=-1)[:, None]
        vis = inside & frags.mask[b, row, col] & (z <= frags.depth[b, row, col] + VISIBLE_DEPTH * size)
        vis &= coverage[idx][b, row, col] > 0.5
        c = images[idx][b, row, col] * vis[..., None]  # (B, V, 3)
        acc = c.sum(0) if acc is None else acc + c.sum(0)
        n = vis.sum(0) if n is None else n + vis.sum(0)
    if n.sum() > 0:
        mean = acc.sum(0) / n.sum()
    else:  # nothing seen (a surface off screen): the frames' mean colour inside the masks
        inside = (coverage[idx_all] > 0.5).to(images.dtype)[..., None]
        mean = (images[idx_all] * inside).sum((0, 1, 2)) / inside.sum().clamp(min=1)
    return torch.where(n[:, None] > 0, acc / n.clamp(min=1)[:, None], mean[None])


def photometric_loss(
    vertices: Tensor, faces: Tensor, camera: Camera, colours: Tensor, images: Tensor, valid: Tensor
) -> Tensor:
    """Mean over the valid covered pixels of |frame - gain * render|, summed over RGB.

    vertices (B, V, 3), faces (F, 3), camera (B cameras), colours (V, 3), images (B, H, W, 3),
    valid (B, H, W) weights (the mask's inside, 0 elsewhere and on frames without a mask). Only
    the pixels that count are interpolated: the animal covers a part of the fit image.
    """
    frags = rasterize(vertices, faces, camera)
    B, H, W = frags.mask.shape
    use = (valid * frags.mask.to(valid.dtype)).reshape(-1)
    pix = torch.nonzero(use > 0).squeeze(1)  # (P,)
    if len(pix) == 0:
        return (vertices.sum() + colours.sum()) * 0.0  # no pixel counts: a zero that keeps the graph
    bary = frags.bary.reshape(-1, 3)[pix]  # (P, 3), differentiable
    rendered = (bary[..., None] * colours[faces[frags.face_ids.reshape(-1)[pix]]]).sum(1)  # (P, 3)
    seen = images.reshape(-1, 3)[pix]
    wgt = use[pix][:, None]
    frame = torch.div(pix, H * W, rounding_mode="floor")
    with torch.no_grad():
        zeros = seen.new_zeros(B, 3)
        seen_sum = zeros.index_add(0, frame, seen * wgt)
        rendered_sum = zeros.index_add(0, frame, rendered * wgt).clamp(min=1e-6)
        gain = (seen_sum / rendered_sum).clamp(0.2, 5.0)  # (B, 3)
    diff = (seen - gain[frame] * rendered).abs().sum(-1, keepdim=True)
    return (diff * wgt).sum() / wgt.sum()
