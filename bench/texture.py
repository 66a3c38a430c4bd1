"""Colour bake benchmark: the bake (`zooctl.fit.texture.bake`) of a finished fit timed again on
its stored character, frames and masks, beside the fit's own recorded timings; optionally a PNG
of the baked character from the input view and from both sides, to look at.

    .venv/bin/python bench/texture.py --store STORE --fit NAME [--repeat 3] [--png views.png]
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import machine  # noqa: E402


def fit_camera(usd_path: str, height: int, width: int):
    """The fit's camera (``/World/Camera`` of its USD output) at the input resolution."""
    from pxr import Usd, UsdGeom

    from zooctl.render.camera import from_usd

    stage = Usd.Stage.Open(usd_path)  # held: its prims die with it
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/Camera"))
    c2w = np.array(UsdGeom.Xformable(cam).ComputeLocalToWorldTransform(0)).T
    return from_usd(
        cam.GetFocalLengthAttr().Get(),
        cam.GetHorizontalApertureAttr().Get(),
        cam.GetVerticalApertureAttr().Get(),
        c2w,
        height,
        width,
        cam.GetHorizontalApertureOffsetAttr().Get(),
        cam.GetVerticalApertureOffsetAttr().Get(),
    )


def views(asset, camera, frame: np.ndarray, t: int) -> np.ndarray:
    """(2H, 2W, 3): the input frame, the baked character through the fit's camera, and seen
    from either side (+-90 degrees around it, raised 15)."""
    from zooctl.render.preview import PreviewRenderer, orbit_camera

    r = PreviewRenderer()
    posed = asset.pose("fit", t).astype(np.float32)
    H, W = frame.shape[:2]
    centre = 0.5 * (posed.max(0) + posed.min(0))
    size = float(np.linalg.norm(posed.max(0) - posed.min(0)))
    a0 = math.atan2(-centre[0], -centre[2])

    def side(az: float) -> np.ndarray:
        a, e = a0 + math.radians(az), math.radians(15.0)
        eye = centre + 1.6 * size * np.array(
            [math.sin(a) * math.cos(e), math.sin(e), math.cos(a) * math.cos(e)]
        )
        return r.render(posed, asset.faces, orbit_camera(eye, centre, H, W, 35.0), asset.vertex_colors)

    top = np.concatenate([frame, r.render(posed, asset.faces, camera, asset.vertex_colors)], 1)
    return np.concatenate([top, np.concatenate([side(90.0), side(-90.0)], 1)], 0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--store", type=Path, required=True, help="the store holding the fit and its video")
    ap.add_argument("--fit", required=True, help="name of a finished fit")
    ap.add_argument("--repeat", type=int, default=3, help="timed bakes (median)")
    ap.add_argument("--png", type=Path, default=None, help="write the views of the baked character here")
    args = ap.parse_args()

    from zooctl.fit.texture import bake
    from zooctl.store.bank import Bank
    from zooctl.store.fits import FitStore
    from zooctl.store.videos import VideoStore

    fits = FitStore(args.store)
    rec = fits.get(args.fit)
    asset = fits.character(args.fit)
    template = Bank(args.store).get(rec["template"])
    video = VideoStore(args.store).get(rec["stored_video"])
    frames, masks = video.frames[: rec["frames"]], video.masks[: rec["frames"]]
    H, W = rec["image_size"]
    camera = fit_camera(rec["outputs"]["usd"], H, W)
    wall, cpu = [], []
    for _ in range(args.repeat):
        t, c = time.perf_counter(), time.process_time()
        baked, info = bake(asset, camera, frames, masks, reference=template.vertices)
        wall.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    info.pop("seconds")
    out = {
        "machine": machine(),
        "fit": args.fit,
        "frames": int(len(frames)),
        "image_size": [H, W],
        "bake_wall_s": statistics.median(wall),
        "bake_cpu_s": statistics.median(cpu),
        "bake": info,
        "fit_timings": rec.get("timings", {}),
    }
    print(json.dumps(out, indent=1))
    if args.png is not None:
        from zooctl.render.preview import save_png

        t = len(frames) // 2
        save_png(args.png, views(baked, camera, frames[t], t))


if __name__ == "__main__":
    main()
