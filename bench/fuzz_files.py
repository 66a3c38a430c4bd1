"""Import fuzz, full run: mutated glTF/GLB/USD files through `bank add` (issue 18).

Every file must end in success or a clear one-line error, within 60 s, under 2 GB of memory,
leaving the store's other files byte-identical (see tests/fuzz/file_mutants.py for the mutations
and the checks; tests/fuzz/test_file_fuzz.py runs a quick subset in `make test`).

    .venv/bin/python bench/fuzz_files.py [--n 600] [--cli 60] [--seed 18] [--out bench/out/fuzz_files.json]
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

from _util import REPO, machine

sys.path.insert(0, str(REPO / "tests" / "fuzz"))
from file_mutants import make_store, mutants, run_cli, run_library, summarize  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, default=600, help="mutated files, all imported in-process")
    ap.add_argument("--cli", type=int, default=60, help="of those, how many also through the CLI")
    ap.add_argument("--seed", type=int, default=18)
    ap.add_argument("--out", type=Path, default=Path("bench/out/fuzz_files.json"))
    args = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="zooctl-fuzz-files-"))
    try:
        t0 = time.perf_counter()
        cases = mutants(work / "files", args.n, args.seed)
        t_gen = time.perf_counter() - t0
        store = work / "store"
        make_store(store)

        def log(o):
            if not o.passed:
                print(f"FAIL {o.via} {o.case.name}: {o.status} {o.detail[:200]}", flush=True)

        t1 = time.perf_counter()
        lib = run_library(cases, store, log)
        t_lib = time.perf_counter() - t1
        step = max(1, len(cases) // max(args.cli, 1))
        t2 = time.perf_counter()
        cli = run_cli(cases[::step][: args.cli], store, log) if args.cli else []
        t_cli = time.perf_counter() - t2
        kinds: dict[str, dict[str, int]] = {}
        for o in lib:
            kinds.setdefault(o.case.kind, {}).setdefault(o.status, 0)
            kinds[o.case.kind][o.status] += 1
        slowest = max(lib + cli, key=lambda o: o.seconds)
        biggest = max(lib + cli, key=lambda o: o.peak_kb)
        report = {
            "machine": machine(),
            "command": " ".join(["bench/fuzz_files.py", *sys.argv[1:]]),
            "files": len(cases),
            "library": summarize(lib),
            "cli": summarize(cli),
            "failures": [
                {"case": o.case.name, "via": o.via, "status": o.status, "detail": o.detail}
                for o in lib + cli
                if not o.passed
            ],
            "by_kind": kinds,
            "cases": [[o.case.name, o.via, o.status, o.detail[:300]] for o in lib + cli],
            "seconds": {"generate": round(t_gen, 1), "library": round(t_lib, 1), "cli": round(t_cli, 1)},
            "slowest": {"case": slowest.case.name, "via": slowest.via, "seconds": round(slowest.seconds, 2)},
            "peak_rss_mb": {
                "case": biggest.case.name,
                "via": biggest.via,
                "mb": round(biggest.peak_kb / 1024),
            },
        }
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(report, indent=1))
        print(json.dumps({k: v for k, v in report.items() if k not in ("by_kind", "failures", "cases")}, indent=1))
        print(f"{len(report['failures'])} failures; report: {args.out}")
        sys.exit(1 if report["failures"] else 0)
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
