"""Retrieval benchmark (issue 6): leave-one-out accuracy over the 28 shared assets and over the
procedural starter bank, `bank add` cost per asset with views and embeddings, and search latency
with a bank of 10,000 synthetic assets (scoring in-process, and the whole `zooctl bank search`).

    .venv/bin/python bench/retrieval.py [--embedder effnet --embedder silhouette] [--views 24]
        [--synthetic 10000] [--skip-loo] [--out bench/out/retrieval.json]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _util import SHARED, machine, time_command

from zooctl.cli._common import print_table
from zooctl.retrieval.benchmark import COLUMNS, loo_benchmark, search_latency, summary_rows, synthetic_bank


def time_once(args: list[str], env: dict) -> float:
    """Wall seconds of one `zooctl ...` run in a new process."""
    exe = Path(sys.executable).with_name("zooctl")
    t = time.perf_counter()
    subprocess.run([str(exe), *args], check=True, capture_output=True, env=dict(os.environ, **env))
    return time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--embedder", action="append", default=None)
    ap.add_argument("--views", type=int, default=24)
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument(
        "--synthetic", type=int, default=10000, help="assets in the synthetic latency bank (0: skip)"
    )
    ap.add_argument("--skip-loo", action="store_true")
    ap.add_argument("--out", type=Path, default=Path("bench/out/retrieval.json"))
    args = ap.parse_args()
    embedders = args.embedder or ["effnet", "silhouette"]
    report = {"machine": machine(), "command": " ".join(sys.argv)}
    tmp = Path(tempfile.mkdtemp(prefix="zooctl-bench-retrieval-"))
    try:
        if not args.skip_loo:
            from zooctl.io.gltf_import import load_gltf
            from zooctl.procedural import starter_assets

            files = sorted((SHARED / "assets").rglob("*.glb"))
            if not files:
                sys.exit(f"bench/retrieval.py needs the shared assets at {SHARED / 'assets'}")
            shared = [load_gltf(f, f.stem) for f in files]
            starter = starter_assets()
            # shared+starter: the shared assets queried against a bank that also holds the starter
            # animals, as a real user's bank (`make demo`) does
            runs = (
                ("shared", shared, None),
                ("shared+starter", shared + starter, [a.name for a in shared]),
                ("starter", starter, None),
            )
            for label, assets, queries in runs:
                r = loo_benchmark(
                    assets,
                    tmp / label,
                    embedders,
                    n_views=args.views,
                    frames=args.frames,
                    progress=lambda msg, i, n: print(f"  [{i}/{n}] {msg}", file=sys.stderr, flush=True),
                    queries=queries,
                )
                report[label] = r
                print_table(
                    COLUMNS,
                    summary_rows(r),
                    title=f"leave-one-out: {r['queries']} queries, bank of {r['assets']} {label} assets ({args.views} views, {args.frames} query frames)",
                )
                print(
                    f"views + embeddings per asset: median {r['index_seconds_per_asset_median']:.2f} s, max {r['index_seconds_per_asset_max']:.2f} s"
                )
        if args.synthetic:
            dims = {"effnet": 1280, "silhouette": 576}
            root = tmp / "synthetic"
            synthetic_bank(root, args.synthetic, dims, n_views=args.views)
            scoring = search_latency(root, dims, frames=args.frames)
            dog = SHARED / "videos" / "dog"
            env = {"ZOOCTL_STORE": str(root)}
            whole = first = repeat = None
            if dog.is_dir():
                whole = time_command(["bank", "search", str(dog)], env=env, repeat=3)
                # a stored video: the first search embeds and caches the query, repeats read the cache
                time_once(["video", "add", str(dog), "--name", "dog", "-q"], env)
                from zooctl.store.videos import VideoStore

                cache = VideoStore(root).cache_dir("dog")
                firsts = []
                for _ in range(3):
                    shutil.rmtree(cache, ignore_errors=True)
                    firsts.append(time_once(["bank", "search", "dog"], env))
                first = statistics.median(firsts)
                repeat = time_command(["bank", "search", "dog"], env=env, repeat=7)
            report["search"] = {
                "assets": args.synthetic,
                "views": args.views,
                "scoring_median_s": scoring["scoring_s"],
                "load_median_s": scoring["load_s"],
                "command_folder_median_s": whole,
                "command_stored_first_median_s": first,
                "command_stored_repeat_median_s": repeat,
            }
            print(
                f"search among {args.synthetic} assets: scoring {1000 * scoring['scoring_s']:.0f} ms, index + pack check {1000 * scoring['load_s']:.0f} ms (medians)"
                + (
                    f"; whole `zooctl bank search`: DAVIS folder {whole:.2f} s, stored video first"
                    f" {first:.2f} s, repeat {repeat:.2f} s (medians)"
                    if whole
                    else ""
                )
            )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=1))
    print(f"machine: {report['machine']}\nwrote {args.out}")


if __name__ == "__main__":
    main()
