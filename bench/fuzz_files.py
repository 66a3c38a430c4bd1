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

from _util import REPO, machine, write_json

sys.path.insert(0, str(REPO / "tests" / "fuzz"))
from file_mutants import Case, make_store, mutants, run_cli, run_library, summarize  # noqa: E402
from gltf_builder import glb_bytes  # noqa: E402


def boundary_glb(
    path: Path, joints: int = 50, clips: int = 6, seconds: float = 555.0, copies: int = 488
) -> Path:
    """A small file just inside the default limits, the most memory a file may ask for: a chain
    of ``joints`` joints, ``clips`` clips of ``seconds`` at 30 fps (6 x 16,651 frames x 50 joints
    = 5.0 million joint-frames), and one 1,024-vertex grid with 8 influences per vertex drawn
    ``copies`` times (primitives naming the same accessors: 499,712 vertices)."""
    import numpy as np

    n = 32
    gx, gy = np.meshgrid(np.arange(n, dtype=np.float32), np.arange(n, dtype=np.float32))
    pos = np.stack([gx.ravel(), gy.ravel(), np.zeros(n * n, np.float32)], 1) / n
    quad = np.array([[0, 1, n], [1, n + 1, n]])
    cells = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]).ravel()
    idx = (cells[:, None, None] + quad[None]).reshape(-1).astype(np.uint32)
    base = np.minimum((pos[:, 1] * joints).astype(np.int64), joints - 8)
    jnt = (base[:, None] + np.arange(8)).astype(np.uint16)  # 8 influences: JOINTS_0 and JOINTS_1
    wts = np.full((n * n, 8), 1 / 8, np.float32)
    ibm = np.tile(np.eye(4, dtype=np.float32), (joints, 1, 1))
    ibm[:, 1, 3] = -np.arange(joints) / joints  # joint k sits at y = k / joints
    times = np.array([0, seconds], np.float32)
    rots = np.array([[0, 0, 0, 1], [0, 0, 0.7071068, 0.7071068]], np.float32)
    blobs = [pos, idx, jnt[:, :4].copy(), wts[:, :4].copy(), ibm.transpose(0, 2, 1).copy(), times, rots]
    blobs += [jnt[:, 4:].copy(), wts[:, 4:].copy()]
    views, binary = [], b""
    for blob in blobs:
        views.append({"buffer": 0, "byteOffset": len(binary), "byteLength": blob.nbytes})
        binary += blob.tobytes()
    acc = [
        {"bufferView": 0, "componentType": 5126, "count": n * n, "type": "VEC3"},
        {"bufferView": 1, "componentType": 5125, "count": len(idx), "type": "SCALAR"},
        {"bufferView": 2, "componentType": 5123, "count": n * n, "type": "VEC4"},
        {"bufferView": 3, "componentType": 5126, "count": n * n, "type": "VEC4"},
        {"bufferView": 4, "componentType": 5126, "count": joints, "type": "MAT4"},
        {"bufferView": 5, "componentType": 5126, "count": 2, "type": "SCALAR"},
        {"bufferView": 6, "componentType": 5126, "count": 2, "type": "VEC4"},
        {"bufferView": 7, "componentType": 5123, "count": n * n, "type": "VEC4"},
        {"bufferView": 8, "componentType": 5126, "count": n * n, "type": "VEC4"},
    ]
    attrs = {"POSITION": 0, "JOINTS_0": 2, "WEIGHTS_0": 3, "JOINTS_1": 7, "WEIGHTS_1": 8}
    prim = {"attributes": attrs, "indices": 1}
    nodes = [{"name": "mesh", "mesh": 0, "skin": 0}]
    nodes += [
        {
            "name": f"j{k}",
            "translation": [0, 1 / joints if k else 0, 0],
            **({"children": [k + 2]} if k < joints - 1 else {}),
        }
        for k in range(joints)
    ]
    anims = [
        {
            "name": f"clip{c}",
            "channels": [{"sampler": 0, "target": {"node": 1 + joints // 2, "path": "rotation"}}],
            "samplers": [{"input": 5, "output": 6}],
        }
        for c in range(clips)
    ]
    doc = {
        "asset": {"version": "2.0"},
        "scenes": [{"nodes": [0, 1]}],
        "nodes": nodes,
        "meshes": [{"primitives": [prim] * copies}],
        "skins": [{"joints": list(range(1, joints + 1)), "inverseBindMatrices": 4}],
        "animations": anims,
        "accessors": acc,
        "bufferViews": views,
        "buffers": [{"byteLength": len(binary)}],
    }
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
        write_json(args.out, report, indent=1)
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
