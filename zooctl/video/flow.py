"""Dense optical flow: OpenCV's DIS estimator, forward and backward, and occlusion masks.

A flow estimator is any object with ``flow(frame_a, frame_b) -> (H, W, 2) float32``: the pixel
displacement (dx, dy) that takes each pixel of ``frame_a`` to ``frame_b``. A learned model only has to
provide that method (see ``zooctl.hookspecs.register_flow_estimators``). One that may be called from
several threads at once sets ``thread_safe = True``: `compute_video_flow` then spreads the frame pairs
over the cores.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from contextlib import nullcontext
from dataclasses import dataclass, field
from functools import lru_cache

import cv2
import numpy as np

from ..errors import UsageError
from .cues import background_motion_residual
from .scratch import working

DIS_PRESETS = {
    "ultrafast": cv2.DISOPTICAL_FLOW_PRESET_ULTRAFAST,
    "fast": cv2.DISOPTICAL_FLOW_PRESET_FAST,
    "medium": cv2.DISOPTICAL_FLOW_PRESET_MEDIUM,
}
FLOW_WORK_SIZE = 640  # longest side DIS works at: masks as good for less CPU (BENCHMARKS.md, Video store)


class DISFlow:
    """Dense Inverse Search flow (Kroeger et al. 2016) on grey images, with OpenCV's variational refinement.

    ``max_size``: longest side the flow is computed at; larger frames are downscaled first and the
    flow comes back up (displacements rescaled) at their size. None or 0: full size. Thread-safe: each
    thread gets its own OpenCV estimator (they keep state between calls).
    """

    thread_safe = True

    def __init__(self, preset: str = "medium", max_size: int | None = FLOW_WORK_SIZE) -> None:
        if preset not in DIS_PRESETS:
            raise UsageError(f"unknown DIS preset {preset!r}", hint=f"use one of {', '.join(DIS_PRESETS)}")
        if max_size and int(max_size) < 16:
            raise UsageError(
                f"flow size must be at least 16 pixels, got {max_size}", hint="or 0 for full size"
            )
        self.preset = preset
        self.max_size = int(max_size) if max_size else None
        self._local = threading.local()

    @property
    def _dis(self):
        dis = getattr(self._local, "dis", None)
        if dis is None:
            dis = self._local.dis = cv2.DISOpticalFlow.create(DIS_PRESETS[self.preset])
        return dis

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
    _residuals: _Residuals | None = field(default=None, init=False, repr=False, compare=False)

    def motion(self, i: int) -> np.ndarray:
        """Frame i's (H, W, 2) motion: its forward flow; the last frame's: its backward flow, reversed."""
        return self.forward[i] if i < len(self.forward) else -np.asarray(self.backward[i - 1])

    def residual(self, i: int) -> np.ndarray:
        """(H, W) float32, read-only: frame i's motion the camera does not explain
        (`zooctl.video.cues.background_motion_residual` of `motion`), made once per frame however
        many steps and threads ask for it (the tracker, the network's looks, the relabelling's bins)."""
        with _RESIDUALS_LOCK:
            if self._residuals is None:
                self._residuals = _Residuals(self)
        return self._residuals.get(i)


_RESIDUALS_LOCK = threading.Lock()


class _Residuals:
    """`VideoFlow.residual`'s store: every frame's residual, kept where the flow is kept (in memory
    for arrays, else in a scratch file), each made by the first thread that asks; the others wait."""

    def __init__(self, flow: VideoFlow) -> None:
        t = len(flow.forward) + 1
        self._flow = flow
        self._store = working(flow.forward, t, tuple(flow.forward.shape[1:3]), np.float32)
        self._made: list[threading.Event | None] = [None] * t
        self._lock = threading.Lock()

    def get(self, i: int) -> np.ndarray:
        i = range(len(self._made))[i]
        with self._lock:
            made = self._made[i]
            mine = made is None
            if mine:
                made = self._made[i] = threading.Event()
        if mine:
            try:
                self._store[i] = background_motion_residual(
                    np.ascontiguousarray(self._flow.motion(i), np.float32)
                )
            except BaseException:
                with self._lock:
                    self._made[i] = None  # the next caller tries again
                made.set()
                raise
            made.set()
        else:
            made.wait()
            if self._made[i] is not made:  # its maker failed
                return self.get(i)
        out = np.asarray(self._store[i])
        if isinstance(self._store, np.ndarray):
            out = out.view()
            out.flags.writeable = False
        return out


def compute_video_flow(
    estimator: object,
    frames: np.ndarray,
    progress: Callable[[int, int], None] | None = None,
    workers: int | None = None,
    occlusion: bool = True,
) -> VideoFlow:
    """Forward and backward flow for every consecutive pair of ``frames`` (T, H, W, 3), T >= 2.

    The pairs are independent: with a ``thread_safe`` estimator they run on ``workers`` threads
    (None: `flow_workers`; OpenCV and NumPy release the GIL), with the same result as one thread.
    ``occlusion`` False: the occlusion masks are left to the caller (None; `pair_occlusion`)."""
    t, h, w = frames.shape[:3]
    fwd = np.empty((t - 1, h, w, 2), np.float32)
    bwd = np.empty((t - 1, h, w, 2), np.float32)
    occ_f = np.empty((t - 1, h, w), bool) if occlusion else None
    occ_b = np.empty((t - 1, h, w), bool) if occlusion else None
    use_grey = hasattr(estimator, "flow_gray")
    fn = estimator.flow_gray if use_grey else estimator.flow  # type: ignore[attr-defined]
    grey = _grey if use_grey else (lambda f: f)

    def pair(i: int) -> None:
        a, b = grey(frames[i]), grey(frames[i + 1])
        fwd[i] = fn(a, b)
        bwd[i] = fn(b, a)
        if occlusion:
            occ_f[i], occ_b[i] = pair_occlusion(fwd[i], bwd[i])

    n = flow_workers() if workers is None else max(int(workers), 1)
    if not getattr(estimator, "thread_safe", False):
        n = 1
    with ThreadPoolExecutor(min(n, t - 1)) if n > 1 else nullcontext() as pool:
        runs = pool.map(pair, range(t - 1)) if pool else map(pair, range(t - 1))
        for done, _ in enumerate(runs, 1):  # in order, so progress counts finished pairs
            if progress:
                progress(done, t - 1)
    return VideoFlow(fwd, bwd, occ_f, occ_b)


def flow_workers() -> int:
    """Threads for the flow of one video: the cores this process may use, at most OMP_NUM_THREADS
    when that is set (batch workers set it to their share) and at most 4."""
    n = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    try:
        n = min(n, int(os.environ.get("OMP_NUM_THREADS", n)))
    except ValueError:
        pass
    return max(min(n, 4), 1)


def warp(
    image: np.ndarray, flow: np.ndarray, interpolation: int = cv2.INTER_LINEAR, border_value: float = 0
) -> np.ndarray:
    """Sample ``image`` at x + flow(x): with flow from frame b to frame a, this pulls a's values onto b's grid.

    ``image`` (H, W[, C]) any OpenCV dtype; ``flow`` (H, W, 2) float32. Outside samples get ``border_value``.
    """
    return _remap(image, _pixel_grid(*flow.shape[:2]) + flow, interpolation, border_value)


def _remap(image: np.ndarray, xy: np.ndarray, interpolation: int, border_value: float = 0) -> np.ndarray:
    """``image`` sampled at the (H, W, 2) float32 positions ``xy``."""
    return cv2.remap(image, xy, None, interpolation, borderMode=cv2.BORDER_CONSTANT, borderValue=border_value)


@lru_cache(maxsize=8)
def _pixel_grid(h: int, w: int) -> np.ndarray:
    """(H, W, 2) float32 x, y of every pixel (read-only: shared between calls and threads)."""
    gx, gy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    grid = np.stack([gx, gy], -1)
    grid.flags.writeable = False
    return grid


def pair_occlusion(forward: np.ndarray, backward: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One frame pair's (H, W, 2) float32 forward and backward flow -> its occlusion masks
    (`VideoFlow`'s ``occlusion_forward[t]`` and ``occlusion_backward[t]``)."""
    return fb_inconsistent(forward, backward), fb_inconsistent(backward, forward)


def fb_inconsistent(
    flow_ab: np.ndarray, flow_ba: np.ndarray, alpha: float = 0.01, beta: float = 0.5
) -> np.ndarray:
    """(H, W) bool: pixels of a where a->b->a does not return home (Sundaram et al. 2010).

    |f + b(x+f)|^2 > alpha (|f|^2 + |b(x+f)|^2) + beta; pixels whose flow leaves the frame count too.
    """
    h, w = flow_ab.shape[:2]
    xy = _pixel_grid(h, w) + flow_ab
    back = _remap(flow_ba, xy, cv2.INTER_LINEAR)
    # in place and per channel: sums over the last axis of (H, W, 2) arrays are NumPy's slow path
    s = flow_ab + back
    s *= s
    lhs = s[..., 0] + s[..., 1]
    sq = flow_ab * flow_ab
    sq += back * back
    rhs = sq[..., 0] + sq[..., 1]
    rhs *= np.float32(alpha)
    rhs += np.float32(beta)
    out = lhs > rhs
    x, y = xy[..., 0], xy[..., 1]
    out |= (x < 0) | (x > w - 1) | (y < 0) | (y > h - 1)
    return out


def flow_to_rgb(flow: np.ndarray, max_magnitude: float | None = None) -> np.ndarray:
    """(H, W, 2) flow -> (H, W, 3) uint8 colour (hue: direction, saturation: speed), the usual colour wheel."""
    mag, ang = cv2.cartToPolar(flow[..., 0].astype(np.float32), flow[..., 1].astype(np.float32))
    scale = max_magnitude if max_magnitude else max(float(np.percentile(mag, 99)), 1e-6)
    hsv = np.empty(flow.shape[:2] + (3,), np.uint8)
    hsv[..., 0] = (ang * (90 / np.pi)).astype(np.uint8)  # OpenCV hue is 0..179
    hsv[..., 1] = np.clip(mag / scale * 255, 0, 255).astype(np.uint8)
    hsv[..., 2] = 255
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)
