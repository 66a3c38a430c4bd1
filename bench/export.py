"""Rig export and preview benchmark: seconds per asset for USD (.usdc) and GLB export of every
shared asset (every starter animal when the shared assets are absent), and preview render frames
per second.

    .venv/bin/python bench/export.py [--repeat 3] [--size 256] [--out bench/out/export.json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import SHARED, machine, median_time  # noqa: E402


def load_assets():
    from zooctl.procedural import starter_assets

    paths = sorted((SHARED / "assets" / "quaternius").glob("*/*.glb"))
    if not paths:
        return "starter animals", starter_assets(0)
    from zooctl.io.gltf_import import load_gltf

    return f"{len(paths)} shared assets", [load_gltf(p, p.stem) for p in paths]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3, help="timed repeats per asset and format (median)")
    ap.add_argument("--size", type=int, default=256, help="preview image size in pixels")
    ap.add_argument("--out", type=Path, default=None, help="write the results as JSON here")
    args = ap.parse_args()

    from zooctl.io.gltf_export import save_glb
    from zooctl.io.usd_export import save_usd
    from zooctl.procedural import build_animal
    from zooctl.render.preview import render_asset

    what, assets = load_assets()
    per_format: dict[str, list[float]] = {"usd": [], "usdz": [], "glb": []}
    with tempfile.TemporaryDirectory() as d:
        for a in assets:
            per_format["usd"].append(median_time(lambda a=a: save_usd(a, Path(d) / "x.usdc"), args.repeat))
            per_format["usdz"].append(median_time(lambda a=a: save_usd(a, Path(d) / "x.usdz"), args.repeat))
            per_format["glb"].append(median_time(lambda a=a: save_glb(a, Path(d) / "x.glb"), args.repeat))
    frames = 30
    render = {}
    for name in ("quadruped", "fish"):
        a = build_animal(name)
        clip = next(iter(a.clips))
        for ss in (1, 2):
            render_asset(a, clip, range(2), size=args.size, supersample=ss)  # warm-up
            t = time.perf_counter()
            render_asset(a, clip, range(frames), size=args.size, supersample=ss)
            render[f"{name} ({a.num_faces} faces) {args.size}px ss{ss}"] = frames / (time.perf_counter() - t)

    print(f"\nMachine: {machine()}; assets: {what}\n")
    print("| export | median s/asset | max s/asset |")
    print("| --- | ---: | ---: |")
    for fmt, ts in per_format.items():
        print(f"| {fmt} | {statistics.median(ts):.3f} | {max(ts):.3f} |")
    print("\n| preview render (CPU, includes skinning) | frames/s |")
    print("| --- | ---: |")
    for k, fps in render.items():
        print(f"| {k} | {fps:.1f} |")
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(
            json.dumps(
                {"machine": machine(), "assets": what, "export_s": per_format, "render_fps": render}, indent=2
            )
        )


if __name__ == "__main__":
    main()
