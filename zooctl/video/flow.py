"""Dense optical flow: OpenCV's DIS estimator, forward and backward, and occlusion masks.

A flow estimator is any object with ``flow(frame_a, frame_b) -> (H, W, 2) float32``: the pixel
displacement (dx, dy) that takes each pixel of ``frame_a`` to ``frame_b``. A learned model only has to
provide that method (see ``zooctl.hookspecs.register_flow_estimators``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import UsageError

DIS_PRESETS = {
    "ultrafast": cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST,
    "fast": cv2.DISOPTICAL_FLOW_PRESET_FAST,
    "medium": cv2.DISOPTICAL_FLOW_PRESET_MEDIUM,
}
FLOW_WORK_SIZE = 640  # longest side DIS works at by default: DAVIS J as at full 854 px, 15% less CPU per add


class DISFlow:
    """Dense Inverse Search flow (Kroeger et al. 2016) on grey images, with OpenCV's variational refinement.

    ``max_size``: longest side the flow is computed at; larger frames are downscaled first and the
    flow comes back up (displacements rescaled) at their size. None or 0: full size.
    """

    def __init__(self, preset: str = "medium", max_size: int | None = FLOW_WORK_SIZE) -> None:
        if preset not in DIS_PRESETS:
            raise UsageError(f"unknown DIS preset {preset!r}", hint=f"use one of {', '.join(DIS_PRESETS)}")
        if max_size and int(max_size) < 16:
            raise UsageError(
                f"flow size must be at least 16 pixels, got {max_size}", hint="or 0 for full size"
            )
        self.preset = preset
        self.max_size = int(max_size) if max_size else None
        self._dis = cv2.DISOpticalFlow.create(DIS_PRESETS[preset])

    def flow(self, frame_a: np.ndarray, frame_b: np.ndarray) -> np.ndarray:
        """(H, W, 3) uint8 RGB x2 -> (H, W, 2) float32 displacement from a to b."""
        return self.flow_gray(_grey(frame_a), _grey(frame_b))

    def flow_gray(self, grey_a: np.ndarray, grey_b: np.ndarray) -> np.ndarray:
        """(H, W) uint8 x2 -> (H, W, 2) float32; skips the colour conversion when grey frames are cached."""
        h, w = grey_a.shape[:2]
        if self.max_size is None or max(h, w) <= self.max_size:
            return self._dis.calc(grey_a, grey_b, None)
        s = self.max_size / max(h, w)
        sw, sh = max(round(w * s), 1), max(round(h * s), 1)
        a, b = (cv2.resize(g, (sw, sh), interpolation=cv2.INTER_AREA) for g in (grey_a, grey_b))
        return resize_flow(self._dis.calc(a, b, None), w, h, cv2.INTER_LINEAR)


def resize_flow(flow: np.ndarray, w: int, h: int, interpolation: int = cv2.INTER_AREA) -> np.ndarray:
    """(H, W, 2) flow -> (h, w, 2), displacements rescaled to the new pixel size."""
    out = cv2.resize(flow, (w, h), interpolation=interpolation)
    out[..., 0] *= w / flow.shape[1]
    out[..., 1] *= h / flow.shape[0]
    return out


def _grey(frame: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(np.ascontiguousarray(frame), cv2.COLOR_RGB2GRAY) if frame.ndim == 3 else frame


@dataclass
class VideoFlow:
    """Flow between consecutive frames of a T-frame video.

    ``forward[t]``: (T-1, H, W, 2), frame t -> t+1. ``backward[t]``: frame t+1 -> t.
    ``occlusion_forward[t]``: (T-1, H, W) bool, pixels of frame t whose forward flow fails the
    forward-backward check (occluded or unreliable). ``occlusion_backward[t]``: the same for pixels of
    frame t+1 and the backward flow.
    """

    forward: np.ndarray
    backward: np.ndarray
    occlusion_forward: np.ndarray
    occlusion_backward: np.ndarray


def compute_video_flow(
    estimator: object, frames: np.ndarray, progress: Callable[[int, int], None] | None = None
) -> VideoFlow:
    """Forward and backward flow for every consecutive pair of ``frames`` (T, H, W, 3), T >= 2."""
    t, h, w = frames.shape[:3]
    fwd = np.empty((t - 1, h, w, 2), np.float32)
    bwd = np.empty((t - 1, h, w, 2), np.float32)
    occ_f = np.empty((t - 1, h, w), bool)
    occ_b = np.empty((t - 1, h, w), bool)
    use_grey = hasattr(estimator, "flow_gray")
    prev = _grey(frames[0]) if use_grey else frames[0]
    for i in range(t - 1):
        nxt = _grey(frames[i + 1]) if use_grey else frames[i + 1]
        fn = estimator.flow_gray if use_grey else estimator.flow  # type: ignore[attr-defined]
        fwd[i] = fn(prev, nxt)
        bwd[i] = fn(nxt, prev)
        occ_f[i] = fb_inconsistent(fwd[i], bwd[i])
        occ_b[i] = fb_inconsistent(bwd[i], fwd[i])
        prev = nxt
        if progress:
            progress(i + 1, t - 1)
    return VideoFlow(fwd, bwd, occ_f, occ_b)


def warp(
    image: np.ndarray, flow: np.ndarray, interpolation: int = cv2.INTER_LINEAR, border_value: float = 0
) -> np.ndarray:
    """Sample ``image`` at x + flow(x): with flow from frame b to frame a, this pulls a's values onto b's grid.

    ``image`` (H, W[, C]) any OpenCV dtype; ``flow`` (H, W, 2) float32. Outside samples get ``border_value``.
    """
    h, w = flow.shape[:2]
    gx, gy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    return cv2.remap(
        image,
        gx + flow[..., 0],
        gy + flow[..., 1],
        interpolation,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=border_value,
    )


def fb_inconsistent(
    flow_ab: np.ndarray, flow_ba: np.ndarray, alpha: float = 0.01, beta: float = 0.5
) -> np.ndarray:
    """(H, W) bool: pixels of a where a->b->a does not return home (Sundaram et al. 2010).

    |f + b(x+f)|^2 > alpha (|f|^2 + |b(x+f)|^2) + beta; pixels whose flow leaves the frame count too.
    """
    h, w = flow_ab.shape[:2]
    back = warp(flow_ba, flow_ab)
    s = flow_ab + back
    lhs = (s * s).sum(-1)
    rhs = alpha * ((flow_ab * flow_ab).sum(-1) + (back * back).sum(-1)) + beta
    gx, gy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    x, y = gx + flow_ab[..., 0], gy + flow_ab[..., 1]
    outside = (x < 0) | (x > w - 1) | (y < 0) | (y > h - 1)
    return (lhs > rhs) | outside


def flow_to_rgb(flow: np.ndarray, max_magnitude: float | None = None) -> np.ndarray:
    """(H, W, 2) flow -> (H, W, 3) uint8 colour (hue: direction, saturation: speed), the usual colour wheel."""
    mag, ang = cv2.cartToPolar(flow[..., 0].astype(np.float32), flow[..., 1].astype(np.float32))
    scale = max_magnitude if max_magnitude else max(float(np.percentile(mag, 99)), 1e-6)
    hsv = np.empty(flow.shape[:2] + (3,), np.uint8)
    hsv[..., 0] = (ang * (90 / np.pi)).astype(np.uint8)  # OpenCV hue is 0..179
    hsv[..., 1] = np.clip(mag / scale * 255, 0, 255).astype(np.uint8)
    hsv[..., 2] = 255
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)
