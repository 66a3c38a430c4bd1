"""Benchmark grid of the differentiable core: renderers and FK + LBS, forward + backward.

Run: ``.venv/bin/python bench/render.py [--device cpu|cuda] [--repeats 5] [--threads N] [--compare] [--out results.json]``.
Prints a Markdown table (median ms per frame) for BENCHMARKS.md and optionally writes JSON.
Scene and method: `zooctl.render.benchmark` (also behind ``zooctl bench render|rig``).

On the CPU the renderers use their C++ kernels (`zooctl.render._kernels`) when these build;
``--compare`` also times the pure-PyTorch path of each renderer in the same run (the path CUDA
and machines without a compiler take) and adds its column and the speed-up.
On a busy machine use ``--threads 1``: with 2+ threads PyTorch's OpenMP workers spin-wait for
each other and lose several-fold when the cores are shared (``OMP_WAIT_POLICY=PASSIVE`` avoids it).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import torch  # noqa: E402

from zooctl.render import _kernels  # noqa: E402
from zooctl.render.benchmark import bench_render, bench_rig  # noqa: E402

# (renderer, faces, size, batch, goal ms/frame on the 2-core CPU box)
GRID = [
    ("soft", 2000, 128, 8, 10.0),
    ("fast", 2000, 128, 8, 2.0),
    ("flow", 2000, 128, 8, 10.0),
    ("soft", 10000, 256, 8, 60.0),
    ("fast", 10000, 256, 8, None),
    ("flow", 10000, 256, 8, None),
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--threads", type=int, default=0, help="torch threads (0: PyTorch's default)")
    ap.add_argument("--compare", action="store_true", help="also time the pure-PyTorch path")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    kernels = args.device == "cpu" and _kernels.available()
    rows = []
    for renderer, faces, size, batch, goal in GRID:
        r = bench_render(
            renderer, faces=faces, size=size, batch=batch, device=args.device, repeats=args.repeats
        )
        r["goal_ms_per_frame"] = goal if args.device == "cpu" else None
        r["path"] = "kernels" if kernels else "pytorch"
        if args.compare and kernels:
            with _kernels.disabled():
                ref = bench_render(
                    renderer, faces=faces, size=size, batch=batch, device=args.device, repeats=args.repeats
                )
            r["pytorch_ms_per_frame"] = ref["ms_per_frame"]
        rows.append(r)
        extra = f" (PyTorch path {r['pytorch_ms_per_frame']:8.2f})" if "pytorch_ms_per_frame" in r else ""
        print(
            f"{renderer:5s} {r['faces']:6d} faces {size:4d}px batch {batch}: {r['ms_per_frame']:8.2f} ms/frame{extra}",
            file=sys.stderr,
        )
    rig = bench_rig(vertices=4000, joints=50, frames=8, device=args.device, repeats=args.repeats)
    print(
        f"fk+lbs {rig['vertices']} vertices, 50 joints: {rig['ms_per_frame']:.2f} ms/frame", file=sys.stderr
    )
    machine = rows[0]["machine"]
    path = "C++ kernels" if kernels else f"PyTorch ({_kernels.error() or 'kernels disabled or not CPU'})"
    print(
        f"\nMachine: {machine}, device {args.device}, threads {torch.get_num_threads()}, renderers: {path}\n"
    )
    compare = any("pytorch_ms_per_frame" in r for r in rows)
    head = "| benchmark | faces | size | batch | median ms/frame (fwd+bwd) |"
    head += " PyTorch path ms/frame | speed-up |" if compare else ""
    print(head + " goal |")
    print("| --- | ---: | ---: | ---: | ---: |" + (" ---: | ---: |" if compare else "") + " ---: |")
    for r in rows:
        goal = "" if r["goal_ms_per_frame"] is None else f"<= {r['goal_ms_per_frame']:g}"
        ref = ""
        if compare:
            p = r.get("pytorch_ms_per_frame")
            ref = f" {p:.2f} | {p / r['ms_per_frame']:.1f}x |" if p else " | |"
        print(
            f"| `zooctl bench render --renderer {r['renderer']} --faces {r['faces']} --size {r['size']} --batch {r['batch']}` | {r['faces']} | {r['size']} | {r['batch']} | {r['ms_per_frame']:.2f} |{ref} {goal} |"
        )
    print(
        f"| `zooctl bench rig` (FK + stretchable LBS, {rig['vertices']} vertices, 50 joints, 8 frames) | | | 8 | {rig['ms_per_frame']:.2f} |"
        + (" | |" if compare else "")
        + " |"
    )
    if args.out:
        args.out.write_text(json.dumps({"renders": rows, "rig": rig}, indent=2))


if __name__ == "__main__":
    main()
