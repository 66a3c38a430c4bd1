"""A photometric term for the fit, measured before it is built in (issue 50, deliverable 2).

    .venv/bin/python bench/photometric.py WEIGHT -- bench run DIR --own-template --preset fast

Runs the zooctl command after ``--`` with one more stage-2 loss term, ``WEIGHT`` x photometric
consistency: each window's vertices are projected into its frames (the video cropped and resized
to the fit resolution, Gaussian-blurred by 1 px so the sampled colour has a gradient), a vertex
counts where the z-buffer (`zooctl.render.raster.rasterize`) says it is the nearest surface
inside the mask; its colour is read bilinearly and divided by the frame's mean colour over the
visible vertices (a per-frame, per-channel gain: robust to exposure and lighting changes), and
the term is the mean L1 distance of those normalised colours from each vertex's mean over the
window's frames (vertices seen in two or more). The gradient reaches the pose through where the
vertices fall in the images. The fit itself is not changed: the term is added by wrapping
`StageRunner._loss` in this process only (BENCHMARKS.md has the result; it did not help, so it
is not in zooctl). The term through the renderer, with learned colours, is ``weights.photometric``
(`zooctl.fit.photometric`).
"""

import sys

import numpy as np
import torch
import torch.nn.functional as F

import zooctl.fit.run as fr
import zooctl.fit.stages as st
from zooctl.fit.inputs import crop_box, fit_resolution

W_PHOTO = float(sys.argv[1])  # the term's weight
IMAGES = {}
_orig_fit = fr.fit_video


def fit_video(video, *a, **k):
    import cv2

    cfg = k.get("cfg") if "cfg" in k else (a[1] if len(a) > 1 else None)
    T = video.masks.shape[0]
    x0, y0, x1, y1 = crop_box(video.masks)
    h, w, _ = fit_resolution(y1 - y0, x1 - x0, cfg.fit_size)
    imgs = np.stack(
        [
            cv2.GaussianBlur(
                cv2.resize(
                    np.asarray(video.frames[t])[y0:y1, x0:x1].astype(np.float32) / 255.0,
                    (w, h),
                    interpolation=cv2.INTER_AREA,
                ),
                (0, 0),
                1.0,
            )
            for t in range(T if cfg.max_frames is None else min(T, cfg.max_frames))
        ]
    )
    IMAGES["cur"] = torch.as_tensor(imgs).permute(0, 3, 1, 2).contiguous()  # (T, 3, h, w)
    return _orig_fit(video, *a, **k)


fr.fit_video = fit_video
import zooctl.fit.job as fj  # noqa: E402

fj.fit_video = fit_video


def photometric(verts, faces, cam, images, coverage):
    from zooctl.render.raster import rasterize

    B, V, _ = verts.shape
    H, W = images.shape[-2:]
    xy, z = cam.project(verts)
    with torch.no_grad():
        frags = rasterize(verts.detach(), faces, cam)
        col = xy[..., 0].detach().floor().long()
        row = xy[..., 1].detach().floor().long()
        inside = (col >= 0) & (col < W) & (row >= 0) & (row < H)
        col, row = col.clamp(0, W - 1), row.clamp(0, H - 1)
        b = torch.arange(B)[:, None]
        size = (verts.detach().amax(1) - verts.detach().amin(1)).norm(dim=-1)[:, None]
        vis = inside & frags.mask[b, row, col] & (z.detach() <= frags.depth[b, row, col] + 0.01 * size)
        vis &= coverage[b, row, col] > 0.5
        vis = vis.float()
    grid = torch.stack((2 * xy[..., 0] / W - 1, 2 * xy[..., 1] / H - 1), -1)[:, :, None]
    c = F.grid_sample(images, grid, mode="bilinear", align_corners=False, padding_mode="border")[
        ..., 0
    ].permute(0, 2, 1)
    gain = (c * vis[..., None]).sum(1) / vis.sum(1).clamp(min=1)[:, None]  # (B, 3)
    cn = c / gain.detach().clamp(min=1e-3)[:, None]
    seen = vis.sum(0)  # (V,)
    mean = (cn * vis[..., None]).sum(0) / seen.clamp(min=1)[:, None]
    use = vis * (seen >= 2).float()[None]
    return ((cn - mean.detach()[None]).abs().sum(-1) * use).sum() / use.sum().clamp(min=1)


_orig_loss = st.StageRunner._loss


def _loss(self, frames, it):
    total, terms = _orig_loss(self, frames, it)
    if self.stage == 2 and W_PHOTO > 0 and len(frames) > 1 and "cur" in IMAGES:
        scene = self.scene
        verts = scene.pose(frames).vertices
        p = W_PHOTO * photometric(
            verts,
            scene.faces,
            scene.camera(len(frames)),
            IMAGES["cur"][frames.cpu()],
            self.targets.masks.coverage[frames],
        )
        total = total + p
        terms["photo"] = p
    return total, terms


st.StageRunner._loss = _loss

from zooctl.cli.main import run  # noqa: E402

sys.exit(run(sys.argv[sys.argv.index("--") + 1 :]))
