"""Nothing lost: concurrent writers and writers killed with SIGKILL at random moments."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from bank_writer import checksum

from zooctl.store.bank import Bank

HERE = Path(__file__).resolve().parent


def _writer(root: Path, prefix: str, count: int) -> subprocess.Popen:
    env = dict(os.environ, PYTHONPATH=str(HERE) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.Popen(
        [sys.executable, str(HERE / "bank_writer.py"), str(root), prefix, str(count)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )


def _added(out: str) -> dict[str, str]:
    return {ln.split()[1]: ln.split()[2] for ln in out.splitlines() if ln.startswith("ADDED ")}


def test_two_processes_adding_different_assets_both_land(tmp_path):
    procs = [_writer(tmp_path, p, 6) for p in ("a", "b")]
    outs = [p.communicate(timeout=300) for p in procs]
    assert all(p.returncode == 0 for p in procs), [o[1] for o in outs]
    names = Bank(tmp_path).names()
    assert names == sorted([f"a{i:03d}" for i in range(6)] + [f"b{i:03d}" for i in range(6)])


def test_sigkill_at_random_moments_never_loses_or_half_writes(tmp_path):
    rng = np.random.default_rng(7)
    confirmed: dict[str, str] = {}
    kills = adds = 0
    for round_ in range(24):
        # Far more adds than fit in a second (an idle machine does ~40 a second): every round is
        # killed, at a random moment after the writer's imports (slow on a loaded machine).
        proc = _writer(tmp_path, f"r{round_ % 3}_", 100_000)
        assert proc.stdout.readline().strip() == "READY", proc.stderr.read()
        time.sleep(float(rng.uniform(0.0, 1.0)))
        proc.send_signal(signal.SIGKILL)
        out, _ = proc.communicate(timeout=60)
        kills += proc.returncode == -signal.SIGKILL
        done = _added(out)
        adds += len(done)
        confirmed.update(done)
        bank = Bank(tmp_path)  # the bank always opens
        listed = bank.names()
        for name in confirmed:
            assert name in listed, f"{name} was added before the kill but is missing"
        for name in listed:  # nothing half-written is listed: every listed asset reads intact
            asset = bank.get(name)
            asset.validate()
            if name in confirmed:
                assert checksum(asset) == confirmed[name]
    assert kills >= 20
    assert adds > 10 and len(confirmed) >= 3  # names repeat across rounds (replace=True)
    report = Bank(tmp_path).cleanup()
    assert not list((tmp_path / "bank" / "assets").glob(".*.tmp"))
    assert report["temporaries"] >= 0
