"""Retrieval benchmark (issue 6): leave-one-out accuracy over the 28 shared assets and over the
procedural starter bank, `bank add` cost per asset with views and embeddings, and search latency
with a bank of 10,000 synthetic assets (scoring in-process, and the whole `zooctl bank search`).

    .venv/bin/python bench/retrieval.py [--embedder effnet --embedder silhouette] [--views 24]
        [--synthetic 10000] [--skip-loo] [--out bench/out/retrieval.json]
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
from pathlib import Path

from _util import SHARED, machine, time_command

from zooctl.cli._common import print_table
from zooctl.retrieval.benchmark import COLUMNS, loo_benchmark, search_latency, summary_rows, synthetic_bank


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
            for label, assets in (("shared", shared), ("starter", starter_assets())):
                r = loo_benchmark(
                    assets,
                    tmp / label,
                    embedders,
                    n_views=args.views,
                    frames=args.frames,
                    progress=lambda msg, i, n: print(f"  [{i}/{n}] {msg}", file=sys.stderr, flush=True),
                )
                report[label] = r
                print_table(
                    COLUMNS,
                    summary_rows(r),
                    title=f"leave-one-out over {r['assets']} {label} assets ({args.views} views, {args.frames} query frames)",
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
            whole = (
                time_command(["bank", "search", str(dog)], env={"ZOOCTL_STORE": str(root)}, repeat=5)
                if dog.is_dir()
                else None
            )
            report["search"] = {
                "assets": args.synthetic,
                "views": args.views,
                "scoring_median_s": scoring["scoring_s"],
                "load_median_s": scoring["load_s"],
                "command_median_s": whole,
            }
            print(
                f"search among {args.synthetic} assets: scoring {1000 * scoring['scoring_s']:.0f} ms, index + pack check {1000 * scoring['load_s']:.0f} ms (medians)"
                + (f", whole `zooctl bank search` {whole:.2f} s (median)" if whole else "")
            )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=1))
    print(f"machine: {report['machine']}\nwrote {args.out}")


if __name__ == "__main__":
    main()
