"""Import fuzz, full run: mutated glTF/GLB/USD files through `bank add` (issue 18).

Every file must end in success or a clear one-line error, within 60 s, under 2 GB of memory,
leaving the store's other files byte-identical (see tests/fuzz/file_mutants.py for the mutations
and the checks; tests/fuzz/test_file_fuzz.py runs a quick subset in `make test`).

    .venv/bin/python bench/fuzz_files.py [--n 1000] [--cli 100] [--seed 18] [--out bench/out/fuzz_files.json]
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
from file_mutants import Case, make_store, mutants, run_cli, run_library, summarize  # noqa: E402
from gltf_builder import glb_bytes, tiny_gltf  # noqa: E402


def boundary_glb(path: Path, joints: int = 100, clips: int = 6, seconds: float = 555.0) -> Path:
    """A small file just inside the default limits: ``joints`` joints (a chain of ancestors above
    the two-bone rig) and ``clips`` clips of ``seconds`` each, 30 fps: 6 x 16,651 frames x 100
    joints = 9.99 million joint-frames. Its import is the most memory a file may ask for."""
    import numpy as np

    doc, binary = tiny_gltf()
    first = len(doc["nodes"])
    for i in range(joints - 2):
        doc["nodes"].append({"name": f"a{i}", "children": [first + i + 1 if i < joints - 3 else 1]})
    doc["scenes"][0]["nodes"] = [0, first]
    times = np.array([0, seconds], np.float32).tobytes()
    doc["bufferViews"].append({"buffer": 0, "byteOffset": len(binary), "byteLength": len(times)})
    doc["accessors"].append(
        {"bufferView": len(doc["bufferViews"]) - 1, "componentType": 5126, "count": 2, "type": "SCALAR"}
    )
    binary += times
    doc["buffers"][0]["byteLength"] = len(binary)
    anim = doc["animations"][0]
    anim["samplers"][0]["input"] = len(doc["accessors"]) - 1
    doc["animations"] = [{**anim, "name": f"clip{k}"} for k in range(clips)]
    path.write_bytes(glb_bytes(doc, binary))
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, default=1000, help="mutated files, all imported in-process")
    ap.add_argument("--cli", type=int, default=100, help="of those, how many also through the CLI")
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
        # the largest import the default limits allow, through the CLI: its peak memory
        big = boundary_glb(work / "boundary.glb")
        edge = run_cli([Case("boundary", "boundary", big)], store, log)[0]
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
                for o in lib + cli + [edge]
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
            "boundary_file": {
                "bytes": big.stat().st_size,
                "status": edge.status,
                "seconds": round(edge.seconds, 1),
                "peak_rss_mb": round(edge.peak_kb / 1024),
            },
        }
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(report, indent=1))
        print(
            json.dumps(
                {k: v for k, v in report.items() if k not in ("by_kind", "failures", "cases")}, indent=1
            )
        )
        print(f"{len(report['failures'])} failures; report: {args.out}")
        sys.exit(1 if report["failures"] else 0)
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
