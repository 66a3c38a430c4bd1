"""Colour bake benchmark: the bake (`zooctl.fit.texture.bake`) of a finished fit timed again on
its stored character, frames and masks, beside the fit's own recorded timings; optionally a PNG
of the baked character from the input view and from both sides, to look at.

    .venv/bin/python bench/texture.py --store STORE --fit NAME [--repeat 3] [--png views.png]
    .venv/bin/python bench/texture.py --store STORE --bench DIR [--ablation full] [--sheet SHEET.png]

``--bench``: every video of a `bench make --appearance textured` folder DIR that `bench run`
fitted into STORE (fit ``bench-<video>-<ablation>``) is baked again three ways on the same fitted
shape (the character with the template's topology, its seams joined again): the template's
colours (what ``--no-texture`` exports), vertex colours, and a texture in a generated atlas (the
default); each is scored by the colour error from the held-out cameras and in sample
(`zooctl.benchdata.appearance.view_psnr`) and its bake timed (wall and CPU seconds). ``--sheet``
instead writes a contact sheet: each fit's exported character beside the truth from the input
and held-out cameras, to look at.
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

    if asset.texture_png is not None:  # unlit: the preview renderer shades vertex colours only
        from zooctl.render.albedo import decode_texture, render_colours

        tex = decode_texture(asset.texture_png)

        class Unlit:
            def render(self, v, faces, cam, _colours):
                rgb, cover = render_colours(v[None], faces, cam, None, asset.uvs, tex)
                img = np.where(cover[0][..., None], rgb[0], 0.8)
                return (np.clip(img, 0, 1) ** (1 / 2.2) * 255).astype(np.uint8)

        r = Unlit()
    else:
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


def joined(character, template):
    """``character`` (a fit baked into a generated atlas: seam vertices split, faces in the
    template's order) on the template's vertices again, wearing the template's colours."""
    import dataclasses

    if character.num_faces != template.num_faces:
        raise SystemExit(f"{character.name}: not the template's faces")
    src = np.zeros(template.num_vertices, np.int64)
    src[template.faces.reshape(-1)] = character.faces.reshape(-1)  # a vertex of the character for each
    return dataclasses.replace(
        character,
        vertices=character.vertices[src],
        faces=template.faces,
        skin_joints=character.skin_joints[src],
        skin_weights=character.skin_weights[src],
        uvs=template.uvs,
        vertex_colors=template.vertex_colors,
        texture_png=template.texture_png,
    ).validate()


def finished_fits(fits, folder: Path, ablation: str):
    """(video folder, fit name, fit record) of every video of ``folder`` whose `bench run` fit
    (``bench-<video>-<ablation>``) finished in the FitStore ``fits``."""
    from zooctl.benchdata.run import bench_videos

    for video in bench_videos(folder):
        name = f"bench-{video.name}-{ablation}".lower()
        try:
            rec = fits.get(name)
        except Exception:  # noqa: BLE001  (not fitted: skipped)
            continue
        if rec.get("status") == "done":
            yield video, name, rec


def compare(store: Path, folder: Path, ablation: str) -> None:
    """The ``--bench`` table (module docstring)."""
    import torch

    from zooctl.benchdata.appearance import view_psnr
    from zooctl.fit.scene import CAMERA_ROTATION
    from zooctl.fit.texture import bake
    from zooctl.render.camera import Camera
    from zooctl.store.bank import Bank
    from zooctl.store.fits import FitStore

    fits, bank = FitStore(store), Bank(store)
    rows = []
    for video, name, rec in finished_fits(fits, folder, ablation):
        template = bank.get(rec["template"])
        plain = joined(fits.character(name), template)
        H, W = rec["image_size"]
        f = rec["camera"]["focal_px"]
        cam = Camera(
            torch.tensor([[f, f, W / 2.0, H / 2.0]], dtype=torch.float32),
            torch.as_tensor(CAMERA_ROTATION[None], dtype=torch.float32),
            torch.zeros(1, 3),
            H,
            W,
        )
        with np.load(video / "video.npz") as z:
            frames, masks = z["frames"][: rec["frames"]], z["masks"][: rec["frames"]]
        row = {
            "video": video.name,
            "template": rec["template"],
            "fit_wall_s": rec["timings"]["total_wall"],
            "fit_bake_s": rec["timings"].get("texture", 0.0),
        }
        for kind, uvs in (("plain", None), ("vertex", False), ("texture", True)):
            asset, secs = plain, (0.0, 0.0)
            if uvs is not None:
                t, c = time.perf_counter(), time.process_time()
                asset, info = bake(plain, cam, frames, masks, reference=template.vertices, make_uvs=uvs)
                secs = (time.perf_counter() - t, time.process_time() - c)
                assert info["mode"] == kind, info
                row["uvs"] = info["uvs"] if kind == "texture" else row.get("uvs")
            res = view_psnr(asset, rec, video)
            row[kind] = {
                "view_psnr": res["view_psnr"],
                "per_view": res["view_psnr_per_view"],
                "input_psnr": res["input_psnr"],
                "bake_wall_s": secs[0],
                "bake_cpu_s": secs[1],
            }
        rows.append(row)
        print(json.dumps(row), flush=True)
    if not rows:
        raise SystemExit(f"no fits of {folder}'s videos in {store} (run `zooctl bench run` first)")
    print(f"\n{machine()}\n")
    print(
        "| video | template | held-out PSNR: template colours / vertex / texture | in sample: template / vertex "
        "/ texture | bake s (wall/CPU): vertex, texture | fit wall s (its bake) |"
    )
    print("|---|---|---|---|---|---|")
    for r in rows + [_mean_row(rows)]:
        k = ("plain", "vertex", "texture")
        print(
            f"| {r['video']} | {r['template']} | "
            + " / ".join(f"{r[x]['view_psnr']:.2f}" for x in k)
            + " | "
            + " / ".join(f"{r[x]['input_psnr']:.2f}" for x in k)
            + f" | {r['vertex']['bake_wall_s']:.1f}/{r['vertex']['bake_cpu_s']:.1f}, "
            + f"{r['texture']['bake_wall_s']:.1f}/{r['texture']['bake_cpu_s']:.1f} "
            + f"| {r['fit_wall_s']:.0f} ({r['fit_bake_s']:.1f}) |"
        )


def contact_sheet(store: Path, folder: Path, ablation: str, png: Path) -> None:
    """``--sheet``: per fitted video of ``folder`` a row of its stored character (as the fit
    exported it) beside the truth, from the input camera and both held-out cameras, at the first
    frame the 3D metrics evaluate, labelled with the video, template, novel-view IoU and PSNR."""
    import cv2

    from zooctl.benchdata.appearance import view_psnr
    from zooctl.render.preview import save_png
    from zooctl.store.fits import FitStore

    fits, rows = FitStore(store), []
    for video, name, rec in finished_fits(fits, folder, ablation):
        res = view_psnr(fits.character(name), rec, video, sheet=True)
        if res is None:
            raise SystemExit(
                f"{video} has no held-out frames: make it with `bench make --appearance textured`"
            )
        img = np.ascontiguousarray(res["sheet"])
        novel = rec.get("metrics", {}).get("novel_view_iou")
        label = (
            f"{video.name} <- {rec['template']}  novel view "
            + ("n/a" if novel is None else f"{novel:.2f}")
            + f"  held-out PSNR {res['view_psnr']:.1f} dB   (truth | fit: input, held-out 1, held-out 2)"
        )
        cv2.putText(img, label, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
        rows.append(img)
    if not rows:
        raise SystemExit(f"no fits of {folder}'s videos in {store} (run `zooctl bench run` first)")
    save_png(png, np.concatenate(rows, axis=0))
    print(f"wrote {png}: {len(rows)} videos")


def _mean_row(rows: list[dict]) -> dict:
    out: dict = {"video": "**mean**", "template": ""}
    out["fit_wall_s"] = float(np.mean([r["fit_wall_s"] for r in rows]))
    out["fit_bake_s"] = float(np.mean([r["fit_bake_s"] for r in rows]))
    for k in ("plain", "vertex", "texture"):
        out[k] = {
            m: float(np.mean([r[k][m] for r in rows]))
            for m in ("view_psnr", "input_psnr", "bake_wall_s", "bake_cpu_s")
        }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--store", type=Path, required=True, help="the store holding the fit and its video")
    ap.add_argument("--fit", help="name of a finished fit")
    ap.add_argument(
        "--bench", type=Path, help="a `bench make --appearance textured` folder `bench run` fitted"
    )
    ap.add_argument("--ablation", default="full", help="with --bench: whose fits (bench-<video>-<ablation>)")
    ap.add_argument("--repeat", type=int, default=3, help="timed bakes (median)")
    ap.add_argument("--png", type=Path, default=None, help="write the views of the baked character here")
    ap.add_argument(
        "--sheet",
        type=Path,
        default=None,
        help="with --bench: write a contact sheet of the fits here instead",
    )
    args = ap.parse_args()
    if args.bench is not None and args.sheet is not None:
        return contact_sheet(args.store, args.bench, args.ablation, args.sheet)
    if args.bench is not None:
        return compare(args.store, args.bench, args.ablation)
    if args.fit is None:
        ap.error("give --fit NAME or --bench DIR")

    from zooctl.fit.texture import bake
    from zooctl.store.bank import Bank
    from zooctl.store.fits import FitStore
    from zooctl.store.videos import VideoStore

    fits = FitStore(args.store)
    rec = fits.get(args.fit)
    template = Bank(args.store).get(rec["template"])
    asset = fits.character(args.fit)
    if asset.num_vertices != template.num_vertices:  # baked into a generated atlas: seams split
        asset = joined(asset, template)
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
