"""Benchmark videos that can see appearance, and the fit's colour error from held-out cameras.

`bench make --appearance textured` dresses the animal in a coat finer than its faces and puts it
over a natural-looking scene, both procedural (nothing is downloaded or shipped):

- the coat: the asset's own colours (or a fawn grey without any) modulated by smooth 3D noise
  laid on its bind-pose surface (random sinusoids, so it moves with the skin): a mottled
  brightness at about a tenth of the animal's length and darker patches at about a third. It is
  not left/right symmetric, as real coats are not;
- the scene: a sky gradient over a ragged horizon of distant hills, and ground of fractal noise
  between two of grass, dry grass, earth and rock, darker and finer towards the horizon.

Shading is as for flat videos (`zooctl.benchdata.make.shade_frames`: one light, an ambient term,
flat per-face Lambert), so a surface point's colour in frame t does not depend on the camera:
the held-out cameras' frames (``gt_view_frames``, the animal over black) show what the input
camera would have seen of the same surface.

``view_psnr`` renders a finished fit's character (its baked texture or vertex colours, unlit)
through those held-out cameras, after the alignment the novel-view IoU uses (`zooctl.fit.metrics`:
the fit in its camera's frame scaled about the camera centre by the voxel-IoU line search, placed
in the benchmark's input camera of the frame), on the frames that metric evaluates, and compares
it with ``gt_view_frames`` on the pixels both the animal and the render cover (where only one
covers, the silhouette is wrong: the novel-view IoU's business). PSNR in dB on 8-bit sRGB, the
squared errors of every such pixel of a camera pooled; ``view_psnr`` the mean over the cameras.
``input_psnr`` is the same through the input camera against the video's own frames (in sample).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..asset import RiggedAsset

APPEARANCES = ("flat", "textured")
_FAWN = (0.45, 0.36, 0.27)  # linear albedo of an asset without colours


def _sinusoids(rng: np.random.Generator, count: int, wavelength: float) -> tuple[np.ndarray, np.ndarray]:
    """Random directions (count, 3) scaled to 2 pi / wavelength (+-30 %), and phases (count,)."""
    d = rng.normal(size=(count, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    k = 2 * np.pi / (wavelength * rng.uniform(0.7, 1.3, count))
    return d * k[:, None], rng.uniform(0, 2 * np.pi, count)


class Coat:
    """The textured coat of one video's animal (module docstring); ``rng`` draws it."""

    def __init__(self, asset: RiggedAsset, rng: np.random.Generator):
        v = np.asarray(asset.vertices, np.float64)
        length = float(np.ptp(v, 0).max()) or 1.0
        self.fine = _sinusoids(rng, 12, 0.1 * length)
        self.patch = _sinusoids(rng, 6, 0.35 * length)
        self.dark = rng.uniform(0.35, 0.6)  # brightness of the patches
        self.colors = (
            np.asarray(asset.vertex_colors, np.float64)
            if asset.vertex_colors is not None
            else np.tile(_FAWN, (asset.num_vertices, 1))
        )
        self.rest = v

    @staticmethod
    def _noise(p: np.ndarray, waves: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
        k, phase = waves
        return np.sin(p @ k.T + phase).sum(-1) / np.sqrt(len(phase) / 2)  # about unit variance

    def albedo(self, faces: np.ndarray, face_ids: np.ndarray, bary: np.ndarray) -> np.ndarray:
        """(N, 3) linear albedo of N surface points: face ids (N,) and barycentrics (N, 3)."""
        tri = faces[face_ids]  # (N, 3)
        p = np.einsum("nk,nkc->nc", bary, self.rest[tri])
        base = np.einsum("nk,nkc->nc", bary, self.colors[tri])
        mottle = 1.0 + 0.25 * np.tanh(self._noise(p, self.fine))
        patches = 1.0 / (1.0 + np.exp(-4.0 * self._noise(p, self.patch)))  # 0..1, sharp edges
        shade = mottle * (1.0 - (1.0 - self.dark) * patches)
        return np.clip(base * shade[:, None], 0, 1)


def _fractal(
    h: int, w: int, rng: np.random.Generator, octaves: int = 6, base: int = 4, ref: int | None = None
) -> np.ndarray:
    """(h, w) float in about [-1, 1]: value noise of ``octaves`` octaves (cubic upsampling), octave
    ``o`` of ``base * 2**o`` cells across the image, or with ``ref`` across every ``ref`` pixels of
    each side (at most one a pixel: a large image gets the grain a ``ref``-pixel one has)."""
    import cv2

    out = np.zeros((h, w), np.float32)
    amp, total = 1.0, 0.0
    for o in range(octaves):
        n = base * 2**o
        if ref is None:
            grid = rng.uniform(-1, 1, (n + 1, n + 1)).astype(np.float32)
        else:
            ny, nx = (min(side, math.ceil(n * side / ref)) + 1 for side in (h, w))
            grid = rng.uniform(-1, 1, (ny, nx)).astype(np.float32)
        out += amp * cv2.resize(grid, (w, h), interpolation=cv2.INTER_CUBIC)
        total += amp
        amp *= 0.55
    return out / total


_GROUNDS = {  # sRGB
    "grass": (86, 118, 52),
    "dry grass": (168, 150, 96),
    "earth": (112, 86, 62),
    "rock": (128, 124, 116),
}


def natural_background(
    h: int, w: int, rng: np.random.Generator, horizon_at: float | None = None, ref: int | None = None
) -> np.ndarray:
    """(h, w, 3) uint8: sky, hills and textured ground (module docstring); the horizon at a random
    height, or at row ``horizon_at * h``; ``ref``: the texture's grain that of a ``ref``-pixel
    image (`_fractal`), for a panorama."""
    names = list(_GROUNDS)
    a, b = rng.choice(len(names), 2, replace=False)
    near, far = np.array(_GROUNDS[names[a]], np.float32), np.array(_GROUNDS[names[b]], np.float32)
    horizon = rng.uniform(0.2, 0.45) * h
    if horizon_at is not None:
        horizon = horizon_at * h
    ridge = horizon + 0.06 * h * _fractal(1, w, rng, 4, 2, ref=ref)[0]  # (w,) the hills' outline
    rows = np.arange(h, dtype=np.float32)[:, None]
    depth = np.clip((rows - horizon) / max(h - horizon, 1.0), 0, 1)  # 0 at the horizon, 1 at the bottom
    mix = 0.5 + 0.5 * _fractal(h, w, rng, ref=ref)
    ground = near * mix[..., None] + far * (1 - mix[..., None])
    grain = _fractal(h, w, rng, 7, 16, ref=ref)[..., None]
    ground = ground * (1.0 + (0.12 + 0.2 * depth[..., None]) * grain) * (0.8 + 0.2 * depth[..., None])
    top, low = np.array([96, 146, 210], np.float32), np.array([196, 214, 228], np.float32)
    t = np.clip(rows / max(horizon, 1.0), 0, 1)[..., None]
    sky = (
        np.broadcast_to(top * (1 - t) + low * t, (h, w, 3))
        + 6 * _fractal(h, w, rng, 3, 2, ref=ref)[..., None]
    )
    hills = np.array([92, 110, 104], np.float32) * (1.0 + 0.1 * _fractal(h, w, rng, 5, 8, ref=ref)[..., None])
    above = (rows < ridge[None])[..., None]  # (h, w, 1)
    hill = ((rows >= ridge[None]) & (rows < horizon + 0.04 * h))[..., None]
    img = np.where(above, sky, np.where(hill, hills, ground))
    return np.clip(img, 0, 255).astype(np.uint8)


# The world scene's panorama: latitudes it covers (degrees) and its resolution (pixels a degree).
_PANO_LAT = (40.0, -80.0)
_PANO_PX_PER_DEG = 8.0


def world_backgrounds(
    rng: np.random.Generator,
    intrinsics: np.ndarray,
    rotations: np.ndarray,
    size: tuple[int, int],
) -> np.ndarray:
    """(T, H, W, 3) uint8: a distant natural scene (`natural_background` laid round the camera as
    an equirectangular panorama, the horizon level) as seen by cameras of ``intrinsics`` (fx, fy,
    cx, cy) and world-to-camera ``rotations`` (T, 3, 3), OpenCV axes, world up +y. The scene is
    fixed in the world, so it moves in the frame as the camera turns, as a real one does; its
    seam lies behind the first camera."""
    import cv2

    top, bottom = _PANO_LAT
    ph, pw = int((top - bottom) * _PANO_PX_PER_DEG), int(360 * _PANO_PX_PER_DEG)
    pano = natural_background(ph, pw, rng, horizon_at=top / (top - bottom), ref=int(40 * _PANO_PX_PER_DEG))
    H, W = size
    fx, fy, cx, cy = (float(v) for v in intrinsics)
    u, v = np.meshgrid(np.arange(W, dtype=np.float64) + 0.5, np.arange(H, dtype=np.float64) + 0.5)
    rays = np.stack([(u - cx) / fx, (v - cy) / fy, np.ones_like(u)], -1)  # camera frame
    ahead = rotations[0].T @ np.array([0.0, 0.0, 1.0])
    lon0 = math.atan2(ahead[0], -ahead[2])
    out = np.empty((len(rotations), H, W, 3), np.uint8)
    for i, R in enumerate(np.asarray(rotations, np.float64)):
        d = rays @ R  # world directions (R^T applied to each row)
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        lat = np.degrees(np.arcsin(np.clip(d[..., 1], -1, 1)))
        lon = (np.degrees(np.arctan2(d[..., 0], -d[..., 2]) - lon0) + 180.0) % 360.0  # start view: 180
        mx = (lon * _PANO_PX_PER_DEG).astype(np.float32)
        my = np.clip((top - lat) * _PANO_PX_PER_DEG, 0, ph - 1).astype(np.float32)
        out[i] = cv2.remap(pano, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
    return out


# -- the colour error ------------------------------------------------------------------------------


def psnr(a: np.ndarray, b: np.ndarray) -> float | None:
    """PSNR in dB of two (N, 3) 8-bit colour arrays; None for no pixels."""
    if len(a) == 0:
        return None
    mse = float(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2))
    return float(10.0 * np.log10(255.0**2 / max(mse, 1e-10)))


def _srgb8(linear: np.ndarray) -> np.ndarray:
    c = np.clip(linear, 0, 1)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055) * 255.0


def view_psnr(
    character: RiggedAsset, record: dict[str, Any], video: Path, sheet: bool = False
) -> dict[str, Any] | None:
    """The colour error of a finished fit (its stored ``character`` and ``record``) of the
    benchmark video folder ``video`` (module docstring): ``view_psnr`` (mean over the held-out
    cameras), ``view_psnr_per_view``, ``input_psnr`` and ``psnr_pixels`` (the pixels compared, all
    cameras). ``sheet``: also ``sheet``, (H, 2 (1 + C) W, 3) uint8 sRGB, the first evaluated frame
    seen by the input camera and each of the C held-out cameras, the truth beside the fit's
    render (over black), to look at. None for a video made without ``gt_view_frames``."""
    from ..fit.metrics import scale_line_search, surface_samples
    from ..fit.scene import CAMERA_ROTATION
    from ..render.albedo import decode_texture, render_colours
    from ..render.camera import Camera

    with np.load(Path(video) / "video.npz") as z:
        if "gt_view_frames" not in z.files:
            return None
        gt = {k: z[k] for k in z.files if k != "flow" and k != "flow_valid"}
    T = int(record["frames"])
    sel = np.asarray(
        record.get("metrics", {}).get("frames_evaluated")
        or np.unique(np.linspace(0, T - 1, min(4, T)).astype(int)),
        int,
    )
    R_fit = np.asarray(CAMERA_ROTATION, np.float64)
    posed = character.pose("fit", sel).astype(np.float64) @ R_fit.T  # the fit's camera frame
    K = np.asarray(gt["intrinsics"], np.float64)
    H, W = gt["masks"].shape[1:]
    world = np.zeros_like(posed)
    for i, t in enumerate(sel):
        R, tr = gt["gt_cam_rotation"][t], gt["gt_cam_translation"][t]
        gv = gt["gt_vertices"][t] @ R.T + tr
        s, _ = scale_line_search(
            surface_samples(posed[i], character.faces), surface_samples(gv, gt["gt_faces"])
        )
        world[i] = (posed[i] * s - tr) @ R  # R^T (p s - t)
    tex = None if character.texture_png is None else decode_texture(character.texture_png)

    def compare(rot: np.ndarray, trans: np.ndarray, frames: np.ndarray, masks: np.ndarray) -> tuple:
        cam = Camera(
            torch.as_tensor(np.tile(K, (len(sel), 1)), dtype=torch.float32),
            torch.as_tensor(rot, dtype=torch.float32),
            torch.as_tensor(trans, dtype=torch.float32),
            H,
            W,
        )
        rgb, cover = render_colours(world, character.faces, cam, character.vertex_colors, character.uvs, tex)
        both = cover & masks
        if sheet:
            tiles.extend((frames[0], np.where(cover[0, ..., None], _srgb8(rgb[0]), 0).astype(np.uint8)))
        return psnr(_srgb8(rgb[both]), frames[both]), int(both.sum())

    tiles: list[np.ndarray] = []
    inp, _ = compare(
        gt["gt_cam_rotation"][sel], gt["gt_cam_translation"][sel], gt["frames"][sel], gt["masks"][sel]
    )

    per_view, pixels = [], 0
    for c in range(gt["gt_view_frames"].shape[0]):
        p, n = compare(
            gt["gt_view_rotation"][c, sel],
            gt["gt_view_translation"][c, sel],
            gt["gt_view_frames"][c, sel],
            gt["gt_view_masks"][c, sel],
        )
        per_view.append(p)
        pixels += n
    ok = [p for p in per_view if p is not None]
    out = {
        "view_psnr": float(np.mean(ok)) if ok else None,
        "view_psnr_per_view": per_view,
        "input_psnr": inp,
        "psnr_pixels": pixels,
    }
    if sheet:
        out["sheet"] = np.concatenate(tiles, axis=1)
    return out


def fit_psnr(store_root: Path, name: str, video: Path) -> dict[str, Any] | None:
    """`view_psnr` of the stored fit ``name``, or None (a flat video, or no stored character)."""
    from ..errors import ZooctlError
    from ..store.fits import FitStore

    if not _has_view_frames(video):
        return None
    fits = FitStore(store_root)
    try:
        return view_psnr(fits.character(name), fits.get(name), video)
    except ZooctlError:
        return None


def _has_view_frames(video: Path) -> bool:
    meta = Path(video) / "meta.json"
    try:
        return json.loads(meta.read_text()).get("appearance") == "textured"
    except (OSError, ValueError):
        return False
