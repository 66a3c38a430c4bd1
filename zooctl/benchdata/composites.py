"""Synthetic training images for the animal segmenter: posed, coated animals over procedural scenes.

Each sample is two frames of a short shot and the animal's mask in the first:

- the animal: a rigged asset (a bank asset or a procedural one) in a random pose (its own clip or
  random bone rotations), a random coat (`zooctl.benchdata.appearance.Coat`, over its own colours or
  a fur palette), one light, seen from a random side and height at a random size (from a small
  distant animal to one that overflows the frame) and place (partly out of frame sometimes);
- the scene (`scene`): sky and hills over textured ground, a close-up of ground (grass, sand,
  rock, snow), water with ripples, or any of these cluttered with man-made things (poles, bars,
  boards, rings: what a course, a fence or a pen puts behind an animal);
- what makes real frames hard: a second animal, an occluder in front, the animal's reflection on
  water (labelled background), motion blur, defocus, noise, JPEG, colour casts;
- motion: the second frame pans the camera (the scene shifts and zooms a little) and moves the
  animal by its own amount (none, sometimes), as a handheld shot of a moving animal does; the
  segmenter reads that through optical flow, as on a real video.

Everything is procedural or comes from the assets given: nothing is downloaded and no video frame
is used, so weights trained on these samples carry only the assets' licence.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from ..asset import RiggedAsset, lbs
from .appearance import Coat, _fractal, natural_background
from .make import clip_motion, random_motion

# Coat palettes of real animals (linear RGB): brown, tan, black, white, grey, orange, cream, dark brown.
FURS = np.array(
    [
        (0.20, 0.11, 0.05),
        (0.45, 0.30, 0.16),
        (0.02, 0.02, 0.02),
        (0.80, 0.78, 0.72),
        (0.30, 0.30, 0.30),
        (0.55, 0.22, 0.06),
        (0.70, 0.60, 0.42),
        (0.08, 0.05, 0.03),
    ]
)
_GROUNDS = np.array(  # sRGB
    [
        (86, 118, 52),
        (168, 150, 96),
        (112, 86, 62),
        (128, 124, 116),
        (222, 222, 226),
        (60, 90, 40),
        (190, 170, 130),
    ],
    np.float32,
)
_WATERS = np.array([(60, 90, 110), (90, 110, 100), (40, 60, 80), (120, 140, 150), (70, 80, 60)], np.float32)


@dataclass
class Sample:
    """One training sample: ``frames`` (2, H, W, 3) uint8, ``mask`` (H, W) bool of the first frame."""

    frames: np.ndarray
    mask: np.ndarray


def _ground(h: int, w: int, rng: np.random.Generator) -> np.ndarray:
    a, b = _GROUNDS[rng.choice(len(_GROUNDS), 2, replace=False)]
    mix = 0.5 + 0.5 * _fractal(h, w, rng)
    img = a * mix[..., None] + b * (1 - mix[..., None])
    grain = _fractal(h, w, rng, 7, int(rng.integers(8, 48)))[..., None]
    return img * (1.0 + rng.uniform(0.1, 0.35) * grain)


def _water(h: int, w: int, rng: np.random.Generator) -> np.ndarray:
    base = _WATERS[rng.integers(len(_WATERS))] * rng.uniform(0.7, 1.3)
    ripples = cv2.resize(_fractal(max(h // 12, 2), w, rng, 6, 8), (w, h), interpolation=cv2.INTER_CUBIC)
    rows = np.linspace(0.85, 1.15, h, dtype=np.float32)[:, None, None]
    img = base * rows * (1.0 + 0.25 * ripples[..., None])
    glints = (ripples > rng.uniform(0.5, 0.8))[..., None]
    return np.where(glints, np.minimum(img * 1.6 + 40, 255), img)


def _clutter(img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Man-made things over a scene: poles, bars, boards, rings and fence rails in strong colours."""
    h, w = img.shape[:2]
    out = np.ascontiguousarray(img, np.float32)
    for _ in range(int(rng.integers(2, 9))):
        colour = tuple(float(c) for c in rng.uniform(0, 255, 3))
        kind = rng.integers(4)
        thick = max(1, int(rng.uniform(0.005, 0.04) * w))
        if kind == 0:  # a pole or bar at any angle
            p = rng.uniform(0, 1, 2) * (w, h)
            a = rng.uniform(0, math.pi)
            d = np.array([math.cos(a), math.sin(a)]) * rng.uniform(0.3, 1.2) * w
            p0, p1 = (p - d).astype(int), (p + d).astype(int)
            cv2.line(out, tuple(map(int, p0)), tuple(map(int, p1)), colour, thick, cv2.LINE_AA)
        elif kind == 1:  # a board
            x, y = rng.uniform(0, 1) * w, rng.uniform(0.2, 1) * h
            bw, bh = rng.uniform(0.05, 0.4) * w, rng.uniform(0.03, 0.3) * h
            cv2.rectangle(out, (int(x), int(y)), (int(x + bw), int(y + bh)), colour, -1)
        elif kind == 2:  # a ring or tyre
            c = (int(rng.uniform(0, 1) * w), int(rng.uniform(0, 1) * h))
            cv2.circle(out, c, int(rng.uniform(0.03, 0.15) * w), colour, thick, cv2.LINE_AA)
        else:  # fence rails
            y0 = rng.uniform(0.3, 0.9) * h
            for k in range(int(rng.integers(1, 4))):
                y = int(y0 + k * rng.uniform(0.04, 0.1) * h)
                cv2.line(out, (0, y), (w, y + int(rng.normal(0, 0.05) * h)), colour, thick, cv2.LINE_AA)
    return out


def _litter(img: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Natural things that are not animals: rocks and logs (large shaded blobs), bushes and leaves
    (many small blobs in greens and browns), gravel."""
    h, w = img.shape[:2]
    out = np.ascontiguousarray(img, np.float32)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float32)
    for _ in range(int(rng.integers(1, 5))):  # rocks: shaded from one side
        c = rng.uniform(0, 1, 2) * (w, h)
        ax = rng.uniform(0.05, 0.3, 2) * w
        a = rng.uniform(0, math.pi)
        dx, dy = xx - c[0], yy - c[1]
        u = (dx * math.cos(a) + dy * math.sin(a)) / ax[0]
        v = (-dx * math.sin(a) + dy * math.cos(a)) / ax[1]
        r = u * u + v * v + 0.3 * _fractal(h, w, rng, 4, 4)
        inside = r < 1
        tone = _GROUNDS[rng.integers(len(_GROUNDS))] * rng.uniform(0.5, 1.2)
        shade = np.clip(0.75 - 0.35 * (u * 0.6 + v * 0.8), 0.3, 1.2)[..., None]
        grain = 1 + 0.15 * _fractal(h, w, rng, 6, 16)[..., None]
        out = np.where(inside[..., None], tone * shade * grain, out)
    if rng.random() < 0.6:  # leaves or gravel
        leafy = rng.random() < 0.6
        for _ in range(int(rng.integers(50, 400))):
            c = (int(rng.uniform(0, w)), int(rng.uniform(0, h)))
            axes = tuple(int(v) + 1 for v in rng.uniform(0.003, 0.02, 2) * w)
            if leafy:
                col = np.array([rng.uniform(20, 110), rng.uniform(60, 160), rng.uniform(10, 70)])
            else:
                col = np.full(3, rng.uniform(60, 200)) + rng.normal(0, 10, 3)
            cv2.ellipse(out, c, axes, float(rng.uniform(0, 180)), 0, 360, tuple(float(v) for v in col), -1)
    return out


def scene(h: int, w: int, rng: np.random.Generator) -> tuple[np.ndarray, bool]:
    """(h, w, 3) float32 sRGB scene and whether it is water (`composite` may add a reflection)."""
    kind = rng.choice(["landscape", "ground", "water"], p=[0.35, 0.4, 0.25])
    if kind == "landscape":
        img = natural_background(h, w, rng).astype(np.float32)
    elif kind == "ground":
        img = _ground(h, w, rng)
    else:
        img = _water(h, w, rng)
    if kind != "water" and rng.random() < 0.6:
        img = _litter(img, rng)
    if rng.random() < 0.3:
        img = _clutter(img, rng)
    return img.astype(np.float32), kind == "water"


class _Camera:
    """A pinhole camera looking at the animal from a random side, the animal at a random size and
    place in the frame."""

    def __init__(self, verts: np.ndarray, h: int, w: int, rng: np.random.Generator) -> None:
        from ..render.preview import fit_camera

        az = rng.uniform(0, 360)
        el = rng.uniform(-5, 45)
        # margin over the tight fit: 1 fills the frame, 5 is a small animal far away
        margin = float(np.exp(rng.uniform(np.log(0.7), np.log(5.0))))
        cam = fit_camera(verts.reshape(-1, 3), h, w, azimuth=az, elevation=el, fov_y=40.0, margin=margin)
        k = cam.intrinsics.clone()
        spread = max(0.0, 1.0 - 1.0 / margin)  # a small animal may be anywhere, a large one near the middle
        k[0, 2] += float(rng.uniform(-0.5, 0.5) * spread * w + rng.normal(0, 0.08) * w)
        k[0, 3] += float(rng.uniform(-0.4, 0.4) * spread * h + rng.normal(0, 0.06) * h)
        self.cam = cam
        self.intrinsics = k
        self.h, self.w = h, w

    def moved(self, dx: float, dy: float):
        from ..render.camera import Camera

        k = self.intrinsics.clone()
        k[0, 2] += dx
        k[0, 3] += dy
        return Camera(k, self.cam.rotation, self.cam.translation, self.h, self.w)


def _coat(asset: RiggedAsset, rng: np.random.Generator) -> Coat:
    coat = Coat(asset, rng)
    if asset.vertex_colors is None or rng.random() < 0.6:
        fur = FURS[rng.choice(len(FURS), 2)]
        # a two-tone coat: a belly or patch colour along one random direction of the body
        v = coat.rest
        d = rng.normal(size=3)
        s = (v - v.mean(0)) @ (d / np.linalg.norm(d))
        t = 1.0 / (1.0 + np.exp(-s / (0.05 * (np.ptp(s) + 1e-9))))
        tone = rng.uniform(0.7, 1.3, 3) ** 0.3
        coat.colors = np.clip((fur[0] * (1 - t[:, None]) + fur[1] * t[:, None]) * tone, 0, 1)
    return coat


def _pose(asset: RiggedAsset, rng: np.random.Generator, gap: int) -> np.ndarray:
    """(2, V, 3) vertices of two frames ``gap`` apart of a random motion of ``asset``."""
    frames = gap + 13
    played = clip_motion(asset, frames, rng) if rng.random() < 0.6 else None
    local = played[0] if played is not None else random_motion(asset, frames, rng, max_deg=45.0)
    t0 = int(rng.integers(0, frames - gap))
    mats = asset.skinning_matrices(local[[t0, t0 + gap]])
    return lbs(asset.vertices, asset.skin_joints, asset.skin_weights, mats).astype(np.float32)


def _render(asset, verts, cams, coat, light, ambient) -> tuple[np.ndarray, np.ndarray]:
    """(2, H, W, 3) float32 sRGB of the animal over black and (2, H, W) bool coverage."""
    from .make import shade_frames

    h, w = cams[0].height, cams[0].width
    black = np.zeros((h, w, 3), np.uint8)
    rgb, masks = shade_frames(asset, verts, cams, light, ambient, black, coat=coat)
    return rgb.astype(np.float32), masks


def _blur_along(img: np.ndarray, dx: float, dy: float) -> np.ndarray:
    n = int(min(max(abs(dx), abs(dy)), 25))
    if n < 2:
        return img
    k = np.zeros((2 * n + 1, 2 * n + 1), np.float32)
    cv2.line(k, (n - int(dx / 2), n - int(dy / 2)), (n + int(dx / 2), n + int(dy / 2)), 1.0, 1)
    k /= max(k.sum(), 1e-6)
    return cv2.filter2D(img, -1, k)


def composite(
    assets: list[RiggedAsset], rng: np.random.Generator, size: tuple[int, int] = (448, 336)
) -> Sample:
    """One training sample (module docstring) of an animal drawn from ``assets``; ``size`` (w, h)."""
    w, h = size
    asset = assets[int(rng.integers(len(assets)))]
    verts = _pose(asset, rng, gap=int(rng.integers(1, 4)))
    cam = _Camera(verts, h, w, rng)
    # the animal's own motion in the image, and the camera's pan (the scene's shift)
    own = rng.normal(0, 0.03, 2) * w if rng.random() < 0.75 else np.zeros(2)
    pan = rng.normal(0, 0.02, 2) * w
    cams = [cam.moved(0, 0), cam.moved(*(own + pan))]
    light = rng.normal(size=3)
    light[1] = abs(light[1]) + 0.3
    light /= np.linalg.norm(light)
    coat = _coat(asset, rng)
    fg, cover = _render(asset, verts, cams, coat, light, float(rng.uniform(0.2, 0.6)))
    pad = int(0.1 * w)
    big, water = scene(h + 2 * pad, w + 2 * pad, rng)
    zoom = 1.0 + rng.normal(0, 0.01)
    shots = []
    for k, shift in enumerate((np.zeros(2), pan)):
        m = np.float32([[zoom**k, 0, pad - shift[0]], [0, zoom**k, pad - shift[1]]])
        m[:, 2] -= (zoom**k - 1) * np.float32([w / 2, h / 2])
        shots.append(
            cv2.warpAffine(
                big, m, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REFLECT
            )
        )
    out = np.stack(shots)
    if water and rng.random() < 0.6:  # the animal's reflection below it: background
        for k in range(2):
            rows = np.flatnonzero(cover[k].any(1))
            if len(rows):
                base = int(rows.max())
                flipped = fg[k][::-1]
                fm = cover[k][::-1]
                shift = 2 * base - h + 1
                ref = np.zeros_like(fg[k])
                rm = np.zeros_like(cover[k])
                if 0 <= shift < h:
                    ref[shift:], rm[shift:] = flipped[: h - shift], fm[: h - shift]
                alpha = rng.uniform(0.25, 0.6)
                rm3 = cv2.GaussianBlur(rm.astype(np.float32), (0, 0), 1.5)[..., None] * alpha
                out[k] = out[k] * (1 - rm3) + cv2.GaussianBlur(ref, (0, 0), 1.5) * 0.7 * rm3
    if rng.random() < 0.15 and len(assets) > 1:  # a second, smaller animal (also an animal)
        other = assets[int(rng.integers(len(assets)))]
        ov = _pose(other, rng, gap=1)
        oc = _Camera(ov, h, w, rng)
        ofg, ocov = _render(other, ov, [oc.moved(0, 0), oc.moved(*pan)], _coat(other, rng), light, 0.4)
        out = np.where(ocov[..., None], ofg, out)
        second = ocov[0]
    else:
        second = None
    fgk = fg.copy()
    if rng.random() < 0.5:  # texture is no cue: the animal in a scene's texture, shaded as its coat was
        tex, _ = scene(h + 2 * pad, w + 2 * pad, rng)
        lum = fg.mean(-1, keepdims=True)
        ref = float(np.median(lum[cover])) if cover.any() else 1.0
        for k, shift in enumerate((np.zeros(2), own + pan)):
            m = np.float32([[1, 0, pad - shift[0]], [0, 1, pad - shift[1]]])
            patch = cv2.warpAffine(
                tex, m, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REFLECT
            )
            fgk[k] = patch * np.clip(lum[k] / max(ref, 1.0), 0.2, 2.0)
    if rng.random() < 0.7:  # hair: fine streaks along one direction, finer than the coat's faces
        streak = cv2.resize(
            _fractal(max(h // int(rng.integers(2, 6)), 2), w, rng, 5, 32),
            (w, h),
            interpolation=cv2.INTER_LINEAR,
        )
        if rng.random() < 0.5:
            streak = cv2.resize(
                _fractal(h, max(w // 4, 2), rng, 5, 32), (w, h), interpolation=cv2.INTER_LINEAR
            )
        fgk = fgk * (1.0 + rng.uniform(0.1, 0.4) * streak[None, ..., None])
    if rng.random() < 0.3:  # motion blur along the animal's own motion
        for k in range(2):
            fgk[k] = _blur_along(fgk[k], *(own * rng.uniform(0.5, 1.5)))
        soft = np.stack([_blur_along(c.astype(np.float32), *(own)) for c in cover])
    else:
        soft = cover.astype(np.float32)
    out = out * (1 - soft[..., None]) + fgk * soft[..., None]
    mask = cover[0].copy()
    if second is not None:
        mask |= second & ~cover[0]
    if rng.random() < 0.2:  # an occluder in front (a post, a branch, a rail)
        occ = np.zeros((h, w), np.uint8)
        ys, xs = np.nonzero(cover[0])
        if len(xs):
            cx, cy = int(rng.choice(xs)), int(rng.choice(ys))
            a = rng.uniform(0, math.pi)
            d = np.array([math.cos(a), math.sin(a)]) * w
            thick = max(2, int(rng.uniform(0.01, 0.05) * w))
            cv2.line(occ, (int(cx - d[0]), int(cy - d[1])), (int(cx + d[0]), int(cy + d[1])), 1, thick)
            colour = rng.uniform(0, 255, 3).astype(np.float32)
            for k in range(2):
                out[k][occ > 0] = colour
            mask &= occ == 0
    # the camera's own faults: colour cast, defocus, noise, compression
    out *= rng.uniform(0.9, 1.1, 3).astype(np.float32) * rng.uniform(0.7, 1.3)
    if rng.random() < 0.3:
        s = rng.uniform(0.5, 2.0)
        out = np.stack([cv2.GaussianBlur(o, (0, 0), s) for o in out])
    out += rng.normal(0, rng.uniform(0, 6), out.shape).astype(np.float32)
    frames = np.clip(out, 0, 255).astype(np.uint8)
    if rng.random() < 0.5:
        q = int(rng.integers(30, 90))
        frames = np.stack(
            [
                cv2.imdecode(cv2.imencode(".jpg", f, [cv2.IMWRITE_JPEG_QUALITY, q])[1], cv2.IMREAD_UNCHANGED)
                for f in frames
            ]
        )
    return Sample(frames=frames, mask=mask)
