"""What a fit leaves behind: ``<name>.usd``, ``<name>.glb``, ``overlay.mp4``, ``loss.png``, ``fit.json``
(and ``novel_view.png`` for a video with held-out views).

USD camera convention: the fit camera is static at the world origin looking down world -Z with
+Y up, so ``/World/Camera`` has an identity transform; its focal length and apertures follow
`zooctl.render.camera.to_usd` for the input video's size (square pixels, centred principal
point). Projecting the animated mesh through it overlays the input frames: the root motion of the
``fit`` animation carries any camera motion of the video.
"""

from __future__ import annotations

import io
import math
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..asset import RiggedAsset
from ..store.fs import write_bytes_atomic, write_json_atomic


def write_usd(asset: RiggedAsset, camera, path: Path) -> Path:
    """The fitted character (one SkelAnimation ``fit``) plus ``/World/Camera``, written atomically."""
    from pxr import Gf, Usd, UsdGeom

    from ..io.usd_export import save_usd
    from ..render.camera import to_usd

    path = Path(path)
    with tempfile.TemporaryDirectory(prefix=".zooctl-usd-", dir=path.parent) as d:
        tmp = Path(d) / path.name
        save_usd(asset, tmp, clips=["fit"])
        stage = Usd.Stage.Open(str(tmp))
        UsdGeom.Xform.Define(stage, "/World")
        attrs = to_usd(camera, 0)
        cam = UsdGeom.Camera.Define(stage, "/World/Camera")
        cam.CreateFocalLengthAttr(attrs["focal_length"])
        cam.CreateHorizontalApertureAttr(attrs["horizontal_aperture"])
        cam.CreateVerticalApertureAttr(attrs["vertical_aperture"])
        cam.CreateHorizontalApertureOffsetAttr(attrs["horizontal_aperture_offset"])
        cam.CreateVerticalApertureOffsetAttr(attrs["vertical_aperture_offset"])
        cam.CreateClippingRangeAttr(Gf.Vec2f(0.01, 1e5))
        UsdGeom.Xformable(cam).AddTransformOp().Set(
            Gf.Matrix4d(np.asarray(attrs["camera_to_world"]).T.tolist())
        )
        cam.GetPrim().SetCustomDataByKey("zooctl:image_size", Gf.Vec2i(camera.width, camera.height))
        stage.GetRootLayer().Save()
        write_bytes_atomic(path, tmp.read_bytes())
        for extra in Path(d).iterdir():  # a texture written beside the layer
            if extra.name != path.name:
                write_bytes_atomic(path.parent / extra.name, extra.read_bytes())
    return path


def bake_colours(
    asset: RiggedAsset, camera, video, template: RiggedAsset | None = None
) -> tuple[RiggedAsset, dict[str, Any]]:
    """The character wearing the colours of ``video`` (a `FitVideo`: its frames inside its masks),
    seen through the fit's ``camera`` at the input resolution, and what the bake did
    (`zooctl.fit.texture.bake`). The unseen side is filled judging symmetry on ``template``'s
    shape when it has the character's vertices (the fit bends the template's symmetry)."""
    from .texture import bake

    same = template is not None and template.vertices.shape == asset.vertices.shape
    return bake(asset, camera, video.frames, video.masks, reference=template.vertices if same else None)


def write_glb(asset: RiggedAsset, path: Path) -> Path:
    """The fitted character as glTF binary, through the registered ``glb`` exporter."""
    from ..io.asset_export import export_asset

    return export_asset(asset, Path(path), "glb", ["fit"])


@torch.no_grad()
def exported_mask_iou(asset: RiggedAsset, camera, masks: np.ndarray, batch: int = 8) -> np.ndarray:
    """(T,) IoU of the exported character's ``fit`` clip (linear blend skinning of the asset the
    USD/GLB hold) projected through ``camera`` (input resolution) with masks (T, H, W) bool."""
    from ..geometry import silhouette_iou
    from ..render.raster import rasterize

    T = len(masks)
    faces = torch.as_tensor(asset.faces, dtype=torch.long)
    out = []
    for s in range(0, T, batch):
        idx = np.arange(s, min(s + batch, T))
        v = torch.as_tensor(asset.pose("fit", idx).astype(np.float32))
        sil = rasterize(v, faces, camera.expand(len(idx))).mask.numpy()
        out.append(silhouette_iou(sil, masks[idx]))
    return np.concatenate(out)


TEAR_RATIO = 2.0


def surface_tear(asset: RiggedAsset, clip: str = "fit", seams: np.ndarray | None = None) -> float:
    """The share of the character's surface edges that its pose tears, over the frames of
    ``clip`` (0-1): an edge is torn when it stretches beyond ``TEAR_RATIO`` times its rest length
    or shrinks below one over it, or when the copies of its end vertices (a flat-shaded or
    UV-split mesh's seams: several vertices at one rest position) move apart so far that some
    pair of them would be. Each frame's lengths are taken relative to their median ratio (a
    pose's overall scale is not a tear). The 197 artists' clips of the 28 shared animals: a mean
    0.2 %, 90th percentile 0.65 %.

    ``seams`` (V, 3): the positions that tell which vertices are copies of one, by default the
    character's own rest positions. A fitted character's rest shape can already be cracked
    (copies whose learned skinning differs are moved apart by its stretched bones), so the fit
    passes its template's vertices."""
    from ..rig.skinning import seam_groups

    points = np.asarray(asset.vertices, np.float64)
    at = points if seams is None else np.asarray(seams, np.float64)
    if at.shape != points.shape:
        raise ValueError(f"seams {at.shape} do not match the character's vertices {points.shape}")
    g = seam_groups(at, np.zeros((len(points), 1), np.int64))  # one node per (template) rest position
    U = int(g.max()) + 1
    e = np.unique(
        np.sort(g[asset.faces.reshape(-1, 3)][:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0
    )
    e = e[e[:, 0] != e[:, 1]]
    count = np.bincount(g, minlength=U)[:, None]
    rest_nodes = np.zeros((U, 3))
    np.add.at(rest_nodes, g, points)
    rest_nodes /= count
    rest = np.linalg.norm(rest_nodes[e[:, 0]] - rest_nodes[e[:, 1]], axis=-1)
    keep = rest > 1e-9 * max(float(rest.max(initial=0.0)), 1e-12)
    e, rest = e[keep], rest[keep]
    n = asset.clips[clip].num_frames
    if len(e) == 0 or n == 0:  # no surface (points, degenerate faces) or no frames: nothing to tear
        return 0.0
    torn = 0.0
    for s in range(0, n, 16):
        for v in asset.pose(clip, np.arange(s, min(s + 16, n))).astype(np.float64):
            nodes = np.zeros((U, 3))
            np.add.at(nodes, g, v)
            nodes /= count
            spread = np.zeros(U)
            np.maximum.at(spread, g, np.linalg.norm(v - nodes[g], axis=-1))  # a crack's half-width
            d = np.linalg.norm(nodes[e[:, 0]] - nodes[e[:, 1]], axis=-1)
            scale = np.exp(np.median(np.log(np.maximum(d, 1e-30) / rest)))
            gap = spread[e[:, 0]] + spread[e[:, 1]]
            longest, shortest = (d + gap) / (rest * scale), (d - gap) / (rest * scale)
            torn += float(((longest > TEAR_RATIO) | (shortest < 1.0 / TEAR_RATIO)).mean())
    return torn / max(n, 1)


TORN_NOTE_SHARE = 0.02  # above every artist's clip of the 28 shared animals (the most: 1.3 %)
TORN_NOTE_WEIGHT = 2.0  # the edge-stretch weight the note recommends


def surface_tear_note(share: float, weight: float) -> str | None:
    """The fit record's note for a character whose pose tears ``share`` of its edges under the
    edge-stretch ``weight`` it was fitted with, or None."""
    if share <= TORN_NOTE_SHARE:
        return None
    return (
        f"the fitted pose tears {100 * share:.1f} % of the surface's edges (artists' clips of the shared "
        f'animals: at most 1.3 %); --config with {{"weights": {{"edge_stretch": {TORN_NOTE_WEIGHT:g}}}}} '
        f"(this fit: {weight:g}) keeps the surface whole for about 0.01 of mask IoU (BENCHMARKS.md, A torn surface)"
    )


# -- overlay video -------------------------------------------------------------------------------


@torch.no_grad()
def overlay_frames(
    asset: RiggedAsset, camera, frames: Any, alpha: float = 0.6, turn_frames: int = 60
) -> Iterator[np.ndarray]:
    """T + turn_frames images (H, 2W, 3) uint8, made one at a time as they are taken (``frames``
    (T, H, W, 3) uint8: an array or a stored video's `FrameArray`, read a frame at a time). First the video: the shaded fitted mesh over each frame,
    outlined in `OUTLINE` (a fit shaded like the animal's own colours would not show), beside the
    fit playing its motion seen from the side (+90 degrees around the animal from the
    input camera, raised 20 degrees), a view the input never shows. Then a turntable: the fit frozen
    at the middle frame (its overlay on the left) while the camera turns once around it, starting
    at the input camera's direction."""
    from ..render.preview import PreviewRenderer, orbit_camera
    from ..render.raster import rasterize

    T, H, W = frames.shape[:3]
    faces = torch.as_tensor(asset.faces, dtype=torch.long)
    renderer = PreviewRenderer()

    def pose(t: int) -> np.ndarray:  # (V, 3), a frame at a time: a long clip's poses are not held
        return asset.pose("fit", t).astype(np.float32)

    first = pose(0)
    size = float(np.linalg.norm(first.max(0) - first.min(0)))

    def around(posed: np.ndarray, azimuth: float, elevation: float):
        # Angles from the input camera (at the origin, +Y up) as seen from the animal's centre.
        centre = 0.5 * (posed.max(0) + posed.min(0))
        a0 = math.atan2(-centre[0], -centre[2])
        e0 = math.atan2(-centre[1], math.hypot(centre[0], centre[2]))
        a, e = a0 + math.radians(azimuth), float(np.clip(e0 + math.radians(elevation), -1.4, 1.4))
        eye = centre + 1.6 * size * np.array(
            [math.sin(a) * math.cos(e), math.sin(e), math.cos(a) * math.cos(e)]
        )
        return renderer.render(posed, asset.faces, orbit_camera(eye, centre, H, W, 35.0), asset.vertex_colors)

    left_mid = None
    for t, frame in enumerate(frames):
        posed = pose(t)
        shaded = renderer.render(posed, asset.faces, camera, asset.vertex_colors)
        mask = rasterize(torch.as_tensor(posed[None]), faces, camera).mask[0].numpy()
        img = np.array(frame, np.uint8)
        img[mask] = (alpha * shaded[mask] + (1 - alpha) * frame[mask]).astype(np.uint8)
        left = _label(_outline(img, mask), "input + fit")
        if t == T // 2:
            left_mid = left
        yield np.concatenate([left, _label(around(posed, 90.0, 20.0), "fit, side view (+90 deg)")], 1)
    mid = T // 2
    posed = pose(mid)
    for k in range(turn_frames):
        ang = 360.0 * k / turn_frames
        right = _label(around(posed, ang, 0.0), f"fit at frame {mid}, {ang:.0f} deg from the input")
        yield np.concatenate([left_mid, right], 1)


OUTLINE = (255, 0, 255)  # magenta: rare in footage of animals


def _outline(img: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``img`` with the boundary of ``mask`` (H, W) bool drawn in `OUTLINE`, about 1/240 of the height wide."""
    import cv2

    contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    img = np.ascontiguousarray(img)
    cv2.drawContours(img, contours, -1, OUTLINE, max(1, round(img.shape[0] / 240)))
    return img


def _label(img: np.ndarray, text: str) -> np.ndarray:
    import cv2

    img = np.ascontiguousarray(img)
    scale = max(img.shape[0] / 640.0, 0.35)
    x, y = 6, int(18 * scale) + 4
    # The outline is the thin text shifted round, not a thicker stroke: OpenCV widens each glyph's
    # advance with the thickness, so a thick outline ran past the white text's end.
    for dx, dy in ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)):
        cv2.putText(img, text, (x + dx, y + dy), cv2.FONT_HERSHEY_SIMPLEX, scale, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(img, text, (x, y), cv2.FONT_HERSHEY_SIMPLEX, scale, (255, 255, 255), 1, cv2.LINE_AA)
    return img


def write_overlay(asset: RiggedAsset, camera, frames: np.ndarray, path: Path, fps: float) -> Path:
    from ..io.video import write_mp4

    return write_mp4(path, overlay_frames(asset, camera, frames), fps)


# -- loss curves ---------------------------------------------------------------------------------

_COLOURS = [
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (127, 127, 127),
    (188, 189, 34),
    (23, 190, 207),
    (0, 0, 0),
    (100, 100, 255),
]


def loss_plot(history: dict[str, list[dict[str, float]]], width: int = 900, height: int = 480) -> np.ndarray:
    """(H, W, 3) uint8: every loss term per step (log scale), stages one after the other."""
    from PIL import Image, ImageDraw

    steps = [(stage, terms) for stage in sorted(history) for terms in history[stage]]
    img = Image.new("RGB", (width, height), (255, 255, 255))
    d = ImageDraw.Draw(img)
    left, right, top, bottom = 60, width - 170, 20, height - 40
    d.rectangle([left, top, right, bottom], outline=(0, 0, 0))
    if not steps:
        d.text((left + 10, top + 10), "no optimisation steps", fill=(0, 0, 0))
        return np.asarray(img)
    names = sorted({k for _, t in steps for k in t}, key=lambda k: (k != "total", k))
    vals = np.array([[abs(t.get(k, np.nan)) for k in names] for _, t in steps], dtype=np.float64)
    pos = vals[np.isfinite(vals) & (vals > 0)]
    lo, hi = (np.log10(pos.min()), np.log10(pos.max())) if len(pos) else (-3.0, 0.0)
    hi = max(hi, lo + 1e-6)
    n = len(steps)

    def xy(i: int, v: float) -> tuple[float, float]:
        x = left + (right - left) * i / max(n - 1, 1)
        y = bottom - (bottom - top) * (np.log10(v) - lo) / (hi - lo)
        return x, y

    for e in range(int(np.floor(lo)), int(np.ceil(hi)) + 1):
        if lo <= e <= hi:
            y = xy(0, 10.0**e)[1]
            d.line([left, y, right, y], fill=(225, 225, 225))
            d.text((8, y - 6), f"1e{e}", fill=(80, 80, 80))
    for k, name in enumerate(names):
        pts = [xy(i, v) for i, v in enumerate(vals[:, k]) if np.isfinite(v) and v > 0]
        col = _COLOURS[k % len(_COLOURS)]
        if len(pts) > 1:
            d.line(pts, fill=col, width=2 if name == "total" else 1)
        d.rectangle([right + 12, top + 16 * k + 4, right + 24, top + 16 * k + 12], fill=col)
        d.text((right + 30, top + 16 * k), name, fill=(0, 0, 0))
    boundary = sum(1 for s, _ in steps if s == "stage1")
    if 0 < boundary < n:
        x = xy(boundary, 10.0**lo)[0]
        d.line([x, top, x, bottom], fill=(150, 150, 150))
        d.text((x + 4, bottom + 6), "stage 2", fill=(80, 80, 80))
    d.text((left, bottom + 6), "stage 1", fill=(80, 80, 80))
    d.text((left + (right - left) // 2 - 40, bottom + 22), "step (|loss|, log scale)", fill=(0, 0, 0))
    return np.asarray(img)


def write_loss_png(history: dict[str, list[dict[str, float]]], path: Path) -> Path:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(loss_plot(history)).save(buf, format="PNG")
    write_bytes_atomic(Path(path), buf.getvalue())
    return Path(path)


# -- the fit against the truth from the cameras it never saw ---------------------------------------

_FIT_ONLY, _TRUTH_ONLY, _BOTH, _NEITHER = (255, 140, 0), (50, 110, 255), (235, 235, 235), (40, 40, 40)


def novel_view_sheet(views: list[tuple[str, np.ndarray, np.ndarray]], frames: list[int]) -> np.ndarray:
    """(H, W, 3) uint8: a row per evaluated frame, a column per camera (`metrics.held_out_silhouettes`:
    name, the fit's silhouettes (S, h, w), the truth's); fit only orange, truth only blue, both
    light grey, each cell labelled with its IoU, under a line that says what is compared."""
    from PIL import Image, ImageDraw

    from ..geometry import silhouette_iou

    rows = []
    for s, t in enumerate(frames):
        cells = []
        for name, fit, truth in views:
            f, g = np.asarray(fit[s], bool), np.asarray(truth[s], bool)
            img = np.empty((*f.shape, 3), np.uint8)
            img[:] = _NEITHER
            img[f & ~g], img[g & ~f], img[f & g] = _FIT_ONLY, _TRUTH_ONLY, _BOTH
            iou = float(silhouette_iou(f[None], g[None])[0])
            cells.append(
                _label(img, f"frame {t}, {name}: IoU {iou:.2f}" if np.isfinite(iou) else f"frame {t}, {name}")
            )
        rows.append(
            np.concatenate([np.pad(c, ((1, 1), (1, 1), (0, 0)), constant_values=255) for c in cells], 1)
        )
    body = np.concatenate(rows, 0)
    head = Image.new("RGB", (body.shape[1], 36), (255, 255, 255))
    d = ImageDraw.Draw(head)
    d.text(
        (6, 4),
        "the fit (orange) against the benchmark's truth (blue), both light grey, placed by mIoU's alignment;",
        fill=(0, 0, 0),
    )
    d.text((6, 19), "novel-view IoU: the held-out columns' mean (cameras the fit never saw)", fill=(0, 0, 0))
    return np.concatenate([np.asarray(head), body], 0)


def write_novel_view_png(
    views: list[tuple[str, np.ndarray, np.ndarray]], frames: list[int], path: Path
) -> Path:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(novel_view_sheet(views, frames)).save(buf, format="PNG")
    write_bytes_atomic(Path(path), buf.getvalue())
    return Path(path)


def stage_summary(history: dict[str, list[dict[str, float]]]) -> dict[str, Any]:
    """Per stage: steps run and the first and last value of every term."""
    out = {}
    for stage, steps in history.items():
        if steps:
            out[stage] = {"steps": len(steps), "first": steps[0], "last": steps[-1]}
        else:
            out[stage] = {"steps": 0, "first": {}, "last": {}}
    return out


def write_fit_json(record: dict[str, Any], path: Path) -> Path:
    write_json_atomic(Path(path), record)
    return Path(path)
