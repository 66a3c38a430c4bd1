"""Embedder throughput (images per second) on CPU with 1 and 2 torch threads, and on CUDA when present;
for effnet also its numpy backend (what a search uses; BLAS threads as OMP_NUM_THREADS sets them).

.venv/bin/python bench/embed.py [--embedder effnet] [--batch 16] [--size 224] [--out bench/out/embed.json]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch
from _util import machine, median_time, write_json

from zooctl.embed.base import get_embedder


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--embedder", action="append", default=None)
    ap.add_argument("--batch", type=int, default=16)
    ap.add_argument("--size", type=int, default=224)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--out", type=Path, default=Path("bench/out/embed.json"))
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    images = rng.integers(0, 256, (args.batch, args.size, args.size, 3), dtype=np.uint8)
    masks = np.zeros((args.batch, args.size, args.size), bool)
    masks[:, args.size // 4 : 3 * args.size // 4, args.size // 5 : 4 * args.size // 5] = True
    report = {
        "machine": machine(),
        "command": " ".join(sys.argv),
        "batch": args.batch,
        "size": args.size,
        "results": [],
    }
    devices = [("cpu", 1), ("cpu", 2)] + ([("cuda", 0)] if torch.cuda.is_available() else [])
    for name in args.embedder or ["effnet", "silhouette"]:
        variants = [(d, t, {}) for d, t in devices]
        if name == "effnet":
            variants = [(d, t, {"backend": "torch"}) for d, t in devices] + [("cpu", 0, {"backend": "numpy"})]
        for device, threads, options in variants:
            if threads:
                torch.set_num_threads(threads)
            emb = get_embedder(name, device=device, **options)
            x = masks if getattr(emb, "input_kind", "rgb") == "mask" else images
            emb.embed_batch(x)  # warm-up
            s = median_time(lambda: emb.embed_batch(x), args.repeat)  # noqa: B023
            row = {
                "embedder": name,
                "device": device,
                "threads": threads or None,
                "backend": getattr(emb, "backend", None),
                "images_per_s": args.batch / s,
            }
            report["results"].append(row)
            label = f"{name}/{row['backend']}" if row["backend"] else name
            print(f"{label:14s} {device:5s} threads={threads or '-'}  {row['images_per_s']:.1f} images/s")
    write_json(args.out, report, indent=1)
    print(f"machine: {report['machine']}\nwrote {args.out}")


if __name__ == "__main__":
    main()
