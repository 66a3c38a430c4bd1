"""Batch throughput and executor overhead (issue 23): 8 short fits with `--executor local --jobs 1`,
`--executor ray --jobs 2` (and `local --jobs 2`), a `--resume` rerun of the finished batch, and
Ray's overhead per task; with the load average before each run (the machine is shared).

    PYTHONPATH=... python bench/batch.py [--videos 8] [--iters 60] [--out bench/out/batch.json]

Each command is the real CLI (`python -m zooctl fit DIR/* ...`, a new process, Ray start-up
included), one run each: the fits are synthetic tube animals (`bench make`), by default 8 frames
of 64 px.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import machine, write_json  # noqa: E402


def load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def zooctl(store: Path, *args: str) -> tuple[float, dict]:
    t = time.perf_counter()
    p = subprocess.run(
        [sys.executable, "-m", "zooctl", "--store", str(store), *args, "--json"],
        capture_output=True,
        text=True,
        env=dict(os.environ, OMP_NUM_THREADS="1"),
    )
    wall = time.perf_counter() - t
    if p.returncode != 0:
        raise SystemExit(f"zooctl {' '.join(args)} failed:\n{p.stderr[-2000:]}")
    return wall, json.loads(p.stdout)


def noop(item, report):
    return item


def ray_overhead(n: int) -> dict:
    """Round trip of a task that does nothing, through the ray executor and the batch driver,
    one at a time on a warm worker: what a task costs beyond its own work."""
    from zooctl.executors import get_executor
    from zooctl.pipelines.batch import BatchItem, run_batch

    ex = get_executor("ray", jobs=1)
    items = [BatchItem(f"i{k}", b"x" * 100_000) for k in range(n)]
    run_batch(ex, noop, items[:4], lambda it, v: {})  # start the worker
    t = time.perf_counter()
    run_batch(ex, noop, items, lambda it, v: {})
    per = (time.perf_counter() - t) / n
    ex.close()
    return {"tasks": n, "seconds_per_task": per}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--videos", type=int, default=8)
    ap.add_argument("--iters", type=int, default=60, help="stage-2 iterations of each fit")
    ap.add_argument("--frames", type=int, default=8, help="frames per video")
    ap.add_argument("--size", type=int, default=64, help="video size in pixels (and the fit's)")
    ap.add_argument("--no-local2", action="store_true", help="skip the `local --jobs 2` run")
    ap.add_argument("--work", type=Path, default=None, help="scratch folder (default: a temporary one)")
    ap.add_argument("--out", type=Path, default=None, help="write the results as JSON here")
    args = ap.parse_args()

    from zooctl.benchdata.make import make_video
    from zooctl.rig.synthetic import tube_asset
    from zooctl.store.bank import Bank

    work = args.work or Path(tempfile.mkdtemp(prefix="zooctl-bench-batch-"))
    store, videos = work / "store", work / "videos"
    for i in range(args.videos):
        asset = tube_asset(bones=3 + i % 3, name=f"t{i}")
        Bank(store).add(asset, replace=True)
        make_video(asset, videos, frames=args.frames, size=args.size, seed=i)
    cfg = work / "config.json"
    cfg.write_text(
        json.dumps(
            {
                "fit_size": args.size,
                "stage1": {"iters": 20, "batch": 8},
                "stage2": {"iters": args.iters, "batch": 4},
                "camera": {"azimuths": 8, "elevations": [10.0], "search_size": 48},
            }
        )
    )
    common = [str(p) for p in sorted(videos.iterdir())] + ["--template", "t0", "--config", str(cfg)]
    res: dict = {"machine": machine(), "videos": args.videos, "runs": {}}
    res |= {"stage2_iters": args.iters, "frames": args.frames, "size": args.size}
    runs = [
        ("local --jobs 1", ["--executor", "local", "--jobs", "1"]),
        ("ray --jobs 2", ["--executor", "ray", "--jobs", "2"]),
        ("ray --jobs 2 --resume (all finished)", ["--executor", "ray", "--jobs", "2", "--resume"]),
        ("local --jobs 2", ["--executor", "local", "--jobs", "2"]),
    ][: 3 if args.no_local2 else 4]
    for label, extra in runs:
        before = load()
        wall, rep = zooctl(store, "fit", *common, *extra, "--out", str(work / "out"))
        done = [i for i in rep["items"] if i["status"] == "done"]
        fit_s = [i["fit_s"] for i in done]
        res["runs"][label] = {
            "wall_s": round(wall, 2),
            "done": rep["done"],
            "skipped": rep["skipped"],
            "sum_fit_s": round(sum(fit_s), 2),
            "commit_s_median": statistics.median([i["commit_s"] for i in done]) if done else None,
            "result_bytes_median": statistics.median([i["result_bytes"] for i in done]) if done else None,
            "load_before": before,
            "load_after": load(),
        }
        print(label, json.dumps(res["runs"][label]), flush=True)
    r1, r2 = res["runs"]["local --jobs 1"], res["runs"]["ray --jobs 2"]
    res["ratio_ray2_over_local1"] = round(r2["wall_s"] / r1["wall_s"], 3)
    res["resume_over_batch"] = round(
        res["runs"]["ray --jobs 2 --resume (all finished)"]["wall_s"] / r2["wall_s"], 3
    )
    # What a task cost beyond its fit in the Ray batch: 2 slots' time not spent fitting, per task.
    res["ray_batch_overhead_per_task_s"] = round((2 * r2["wall_s"] - r2["sum_fit_s"]) / args.videos, 2)
    before = load()
    res["ray_noop"] = ray_overhead(40) | {"load_before": before}
    print(json.dumps(res, indent=2))
    if args.out:
        write_json(args.out, res)


if __name__ == "__main__":
    main()
