"""Asset-bank benchmark: adds per second, and `bank list` / `bank show` latency as whole commands
with 1,000 assets in the bank.

    .venv/bin/python bench/bank.py [--assets 1000] [--out bench/out/bank.json]
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

from _util import SHARED, machine, time_command, write_json

from zooctl.io.gltf_import import load_gltf
from zooctl.store.bank import Bank


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--assets", type=int, default=1000)
    ap.add_argument("--out", type=Path, default=Path("bench/out/bank.json"))
    args = ap.parse_args()
    files = sorted((SHARED / "assets").rglob("*.glb"))
    if not files:
        sys.exit(f"bench/bank.py needs the shared assets at {SHARED / 'assets'}")
    root = Path(tempfile.mkdtemp(prefix="zooctl-bench-bank-"))
    try:
        env = {"ZOOCTL_STORE": str(root), "ZOOCTL_VIEWS": "0"}  # views: see bench/retrieval.py
        # 1. import + store, whole command: all 28 files in one `bank add`
        t = time.perf_counter()
        import subprocess

        subprocess.run(
            [str(Path(sys.executable).with_name("zooctl")), "bank", "add", *map(str, files)],
            check=True,
            capture_output=True,
            env=dict(__import__("os").environ, **env),
        )
        cli_rate = len(files) / (time.perf_counter() - t)
        # 2. library adds until the bank holds --assets assets (import once, store many)
        assets = [load_gltf(f, f.stem) for f in files]
        bank = Bank(root)
        t = time.perf_counter()
        n = len(files)
        i = 0
        while n < args.assets:
            a = assets[i % len(assets)]
            a.name = f"{a.name.split('__')[0]}__{i:05d}"
            bank.add(a)
            n += 1
            i += 1
        store_rate = i / (time.perf_counter() - t) if i else float("nan")
        list_s = time_command(["bank", "list"], env)
        list_json_s = time_command(["bank", "list", "--json"], env)
        show_s = time_command(["bank", "show", "Fox"], env)
        show_json_s = time_command(["bank", "show", "Fox", "--json"], env)
        res = {
            "machine": machine(),
            "bank_size": n,
            "cli_add_assets_per_s (import+store, 28 glTF files in one command)": round(cli_rate, 2),
            "library_store_assets_per_s (Bank.add of imported assets)": round(store_rate, 2),
            "bank_list_s": round(list_s, 3),
            "bank_list_json_s": round(list_json_s, 3),
            "bank_show_s": round(show_s, 3),
            "bank_show_json_s": round(show_json_s, 3),
        }
        write_json(args.out, res)
        print(json.dumps(res, indent=2))
    finally:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
