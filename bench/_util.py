"""Shared benchmark helpers: timing whole commands, describing the machine, writing results."""

from __future__ import annotations

import json
import os
import platform
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
# The shared test data beside the checkout; ZOOCTL_BENCH_SHARED names another copy (a device
# machine receives the repository alone: `bench/gpu_check.sh` carries the files it needs).
SHARED = Path(os.environ.get("ZOOCTL_BENCH_SHARED") or REPO.parent / "shared" / "data")


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}"


def median_time(fn: Callable[[], object], repeat: int = 7) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def time_command(args: list[str], env: dict | None = None, repeat: int = 7) -> float:
    """Median wall time of a whole `zooctl ...` command (new process each time)."""
    exe = Path(sys.executable).with_name("zooctl")
    e = dict(os.environ, **(env or {}))

    def run():
        subprocess.run([str(exe), *args], check=True, capture_output=True, env=e)

    run()  # warm the page cache
    return median_time(run, repeat)


def write_json(path: Path, results: object, indent: int = 2) -> None:
    """``results`` as JSON in ``path`` (its folder made)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(results, indent=indent))


def videos_to_log(folder: str | Path, part: str, out: Path) -> list[Path]:
    """The benchmark videos of ``folder`` in part ``I/N`` of them (every N-th from the I-th),
    less those a JSON-lines log ``out`` already has a line for (its ``video``)."""
    from zooctl.benchdata.run import bench_videos

    i, n = (int(x) for x in part.split("/"))
    done = set()
    if out.is_file():
        done = {json.loads(line)["video"] for line in out.read_text().splitlines() if line.strip()}
    return [v for v in bench_videos(Path(folder))[i - 1 :: n] if v.name not in done]


def add_log_parser(sub) -> object:
    """The ``log`` subcommand of a benchmark that logs one JSON line per video (``folder``,
    ``--store``, ``--out``, ``--part``: see `videos_to_log`); ``sub`` from ``add_subparsers``."""
    a = sub.add_parser("log")
    a.add_argument("folder")
    a.add_argument("--store", required=True)
    a.add_argument("--out", required=True)
    a.add_argument("--part", default="1/1")
    return a
