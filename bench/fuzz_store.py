"""Damaged-store fuzz, the full run (issue 18): N damaged store states from a fixed seed, each
put to the usual commands (tests/fuzz/store_fuzz.py says what a state is and what passes).

    python bench/fuzz_store.py [--states 120] [--seed 18] [--assets 4] [--json results.json]

Prints the counts for BENCHMARKS.md and every state that failed; exits 1 if any did.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent / "tests" / "fuzz")]

from _util import SHARED, machine  # noqa: E402
from store_fuzz import PERMISSIONS_APPLY, build_base, plan, run_state, summarize  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--states", type=int, default=120)
    ap.add_argument("--seed", type=int, default=18)
    ap.add_argument("--assets", type=int, default=4, help="shared assets in the base store")
    ap.add_argument("--json", type=Path, help="write every state's record here")
    ap.add_argument(
        "--code", type=Path, default=HERE.parent, help="run the commands with the zooctl of this checkout"
    )
    a = ap.parse_args()
    assets = sorted((SHARED / "assets" / "quaternius").glob("*/*.glb"))
    videos = SHARED / "videos"
    if len(assets) < a.assets + 1 or not (videos / "cows").is_dir():
        print(f"the shared assets and videos are needed (looked in {SHARED})", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="zooctl-fuzz-") as tmp:
        tmp_p = Path(tmp)
        t = time.perf_counter()
        base_root = tmp_p / "base"
        base = build_base(base_root, assets[: a.assets], videos / "cows")
        print(
            f"base store: {len(base['assets'])} assets, 1 video ({time.perf_counter() - t:.1f} s)", flush=True
        )
        records = []
        t = time.perf_counter()
        for i, (seed, kind) in enumerate(plan(a.states, a.seed)):
            work = tmp_p / f"s{i:04d}"
            work.mkdir()
            rec = run_state(base_root, base, work, seed, kind, assets[a.assets], code=a.code)
            records.append(rec)
            mark = "FAIL" if rec["problems"] else "ok"
            print(
                f"{i:4d} {mark:4s} {rec['seconds']:6.1f} s  {kind:12s} {'; '.join(rec['damage'])}", flush=True
            )
            for p in rec["problems"]:
                print(f"       {p}", flush=True)
            shutil.rmtree(work, ignore_errors=True)
        wall = time.perf_counter() - t
    s = summarize(records)
    slowest = max(records, key=lambda r: r["seconds"])
    print(f"\nmachine: {machine()}; permissions apply: {PERMISSIONS_APPLY}; code: {a.code}")
    print(
        f"{s['states']} states ({len(s['kinds'])} kinds), {s['commands']} commands: {s['ok']} succeeded, "
        f"{s['clear_errors']} clear one-line errors; {s['failed_states']} states failed; "
        f"{wall:.0f} s in all, slowest state {slowest['seconds']:.1f} s"
    )
    if a.json:
        a.json.write_text(json.dumps({"summary": s, "records": records}, indent=1))
    return 1 if s["failed_states"] else 0


if __name__ == "__main__":
    sys.exit(main())
