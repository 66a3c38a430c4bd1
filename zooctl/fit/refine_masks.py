"""Analysis by synthesis: a finished fit re-segments its video, then the template is fitted again.

The fitted character, posed by its ``fit`` clip and projected through the fitted camera at the
input resolution (the asset the USD/GLB hold, as `zooctl.fit.outputs.exported_mask_iou` sees it),
is a shape prior for each frame (`zooctl.video.shape_prior`): legs and tails the colour model
dropped come back, riders, wakes and reflections no animal of this shape covers go. One fit of
the same template, from the same start, then runs on the refined masks.

The video's masks are never changed: the refined masks, the prior and the refit's own
reprojection go to ``refined_masks.npz`` in the folder given (`save_refined`, read back with
`load_refined`), and the refit's video names them (``mask_source``).

Measured on the seven shared real videos (``bench/refine_masks.py``, BENCHMARKS.md): it does not
help there, so `zooctl fit` does not offer it; this is the method the benchmark runs.
"""

from __future__ import annotations

import dataclasses
import io
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..store.fs import write_bytes_atomic
from ..video.shape_prior import PriorOptions, refine_masks
from .run import FitResult, Reporter, fit_video

REFINED_FILE = "refined_masks.npz"
REFINED_SUFFIX = " refined by the fit's shape"  # what a refit's mask_source adds to the masks' own


@torch.no_grad()
def reprojection(result: FitResult, batch: int = 8) -> np.ndarray:
    """(T, H, W) bool: the exported character of ``result`` rasterised through its camera at the
    input resolution, frame by frame."""
    from ..render.raster import rasterize
    from .fitted_asset import fitted_asset

    asset = fitted_asset(result.scene, result.template, result.video.name, result.video.fps)
    cam = result.input_camera().to("cpu")
    faces = torch.as_tensor(asset.faces, dtype=torch.long)
    T = result.video.num_frames
    out = []
    for s in range(0, T, batch):
        idx = np.arange(s, min(s + batch, T))
        v = torch.as_tensor(asset.pose("fit", idx).astype(np.float32))
        out.append(rasterize(v, faces, cam.expand(len(idx))).mask.numpy().astype(bool))
    return np.concatenate(out)


def mask_iou(a: np.ndarray, b: np.ndarray) -> float | None:
    """Mean IoU over the frames of two (T, H, W) bool stacks, frames empty in both left out."""
    inter = (a & b).reshape(len(a), -1).sum(1)
    union = (a | b).reshape(len(a), -1).sum(1)
    keep = union > 0
    return round(float((inter[keep] / union[keep]).mean()), 4) if keep.any() else None


def refine_and_refit(
    result: FitResult,
    out_dir: Path,
    reporter: Reporter | None = None,
    opts: PriorOptions = PriorOptions(),
) -> tuple[FitResult, dict[str, Any]]:
    """Re-segment ``result.video`` with ``result``'s reprojection and fit its template again on the
    refined masks (module docstring). Returns the refit and what the record keeps of it; the masks
    are written to ``out_dir/refined_masks.npz``."""
    video, cfg = result.video, result.config
    T = video.num_frames
    original = np.stack([np.asarray(video.masks[i], bool) for i in range(T)])
    t0 = time.perf_counter()
    prior = reprojection(result)
    if reporter is not None:
        reporter.message("re-segmenting the frames with the fitted character as a shape prior")
        reporter.stage("refine masks", T)
    refined = refine_masks(
        video.frames, original, prior, opts, None if reporter is None else (lambda i: reporter.step({}))
    )
    refine_s = time.perf_counter() - t0
    if not refined.any():  # nothing of the prior held up: the fit stays on the masks it had
        return result, {"kept": "original", "reason": "the refined masks are empty", "seconds": refine_s}
    refit_video = dataclasses.replace(
        video, masks=refined, mask_source=video.mask_source + REFINED_SUFFIX, cache={}
    )
    start = result.camera_init.get("view_trial", {}).get("start", "search")
    if reporter is not None:
        reporter.message("fitting again on the refined masks")
    t1 = time.perf_counter()
    refit = fit_video(refit_video, result.template, cfg, reporter, start=start)  # no checkpoints:
    # a resume finishes the first fit from its state and refines again
    refit_s = time.perf_counter() - t1
    after = reprojection(refit)
    path = save_refined(Path(out_dir) / REFINED_FILE, refined, prior, after)
    for k in ("camera", "stage1", "stage2"):  # the first fit's share, kept beside the refit's
        if k in result.timings:
            refit.timings[f"first_fit_{k}"] = result.timings[k]
    refit.timings["refine_masks"] = refine_s
    info = {
        "file": str(path),
        "from_masks": video.mask_source,
        "options": dataclasses.asdict(opts),
        "start": start,
        "changed_pixels": round(float((refined != original).mean()), 5),
        "mask_area_ratio": round(float(refined.sum() / max(original.sum(), 1)), 4),
        "before": {
            "mask_iou": mask_iou(prior, original),
            "masks_iou_refined": mask_iou(original, refined),
            "camera_init": {k: result.camera_init.get(k) for k in ("focal_px", "search_iou")},
        },
        "after": {"mask_iou": mask_iou(after, refined), "mask_iou_original": mask_iou(after, original)},
        "seconds": {"refine": round(refine_s, 3), "refit": round(refit_s, 3)},
    }
    return refit, info


def save_refined(path: Path, refined: np.ndarray, prior: np.ndarray, refit: np.ndarray) -> Path:
    """Write the (T, H, W) bool stacks packed to bits, atomically."""
    buf = io.BytesIO()
    np.savez_compressed(
        buf,
        shape=np.array(refined.shape),
        masks=np.packbits(refined),
        prior=np.packbits(prior),
        refit=np.packbits(refit),
    )
    write_bytes_atomic(path, buf.getvalue())
    return path


def load_refined(path: Path) -> dict[str, np.ndarray]:
    """``masks`` (refined), ``prior`` (the first fit's reprojection) and ``refit`` (the refit's),
    each (T, H, W) bool."""
    with np.load(path) as z:
        shape = tuple(int(s) for s in z["shape"])
        n = int(np.prod(shape))
        return {
            k: np.unpackbits(z[k], count=n).reshape(shape).astype(bool) for k in ("masks", "prior", "refit")
        }


__all__ = [
    "REFINED_FILE",
    "REFINED_SUFFIX",
    "load_refined",
    "refine_and_refit",
    "reprojection",
    "save_refined",
]
