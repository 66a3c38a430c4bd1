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


def stored_fits_parser(doc: str):
    """The command line of a script over a store's benchmark fits: ``--store STORE [FIT ...]
    [--json OUT]`` (add more with ``add_argument`` before ``parse_args``)."""
    import argparse

    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--store", required=True, type=Path)
    ap.add_argument("fits", nargs="*", help="fit names (default: every fit of the store)")
    ap.add_argument("--json", type=Path, default=None, help="also write the lines here")
    return ap


def stored_bench_fits(store: Path, names: list[str] | None = None, need: str = "vertices"):
    """Yield (name, record, result) for each finished fit of ``store`` (``names``, default every
    fit) whose source is a benchmark video with truth ``need``: the fit reloaded from its
    ``state.pt`` (`zooctl.fit.run.fit_video` resumed from the finished state runs no iteration)."""
    from zooctl.fit.config import FitConfig, preset
    from zooctl.fit.inputs import load_bench_video
    from zooctl.fit.run import fit_video
    from zooctl.store.bank import Bank
    from zooctl.store.fits import FitStore

    fits, bank = FitStore(store), Bank.open(store)
    for name in names or fits.names():
        rec = fits.get(name)
        if rec.get("status") != "done" or not fits.state_path(name).is_file():
            continue
        state = fits.load_state(name)
        cfg = FitConfig.from_dict(state["config"], preset(state["config"].get("preset", "fast")))
        video = load_bench_video(Path(rec["source"]))
        if video.gt is None or need not in video.gt:
            continue
        yield name, rec, fit_video(video, bank.get(rec["template"]), cfg, resume=state)


def finish_lines(lines: list[str], summary: dict, out: Path | None) -> None:
    """A per-fit benchmark's JSON lines closed by its ``summary``: printed, and written to ``out``
    when given (one JSON object a line)."""
    lines.append(json.dumps(summary))
    print(lines[-1])
    if out:
        out.write_text("\n".join(lines) + "\n")
