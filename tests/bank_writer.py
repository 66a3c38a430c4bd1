"""Child process for the crash tests: adds synthetic assets to a bank in a loop.

Prints ``READY`` once imported (so the parent times its kill from there, whatever the machine's
load) and ``ADDED <name> <checksum>`` (flushed) after each `Bank.add` returns, so the parent knows
which adds completed before it SIGKILLs this process.
"""

from __future__ import annotations

import sys
import zlib
from pathlib import Path

import numpy as np

from zooctl.asset import Clip, RiggedAsset
from zooctl.store.bank import Bank


def synthetic(name: str, seed: int, V: int = 20000, J: int = 40, T: int = 120) -> RiggedAsset:
    rng = np.random.default_rng(seed)
    parents = np.arange(-1, J - 1, dtype=np.int32)
    rest = np.tile(np.eye(4), (J, 1, 1))
    rest[1:, 1, 3] = 0.1
    q = rng.normal(size=(T, J, 4)).astype(np.float32)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    w = rng.random((V, 4)).astype(np.float32)
    w /= w.sum(1, keepdims=True)
    return RiggedAsset(
        name=name,
        vertices=rng.normal(size=(V, 3)).astype(np.float32),
        faces=rng.integers(0, V, size=(2 * V, 3)).astype(np.int32),
        joint_names=[f"j{i}" for i in range(J)],
        parents=parents,
        rest_local=rest,
        inverse_bind=np.tile(np.eye(4), (J, 1, 1)),
        skin_joints=rng.integers(0, J, size=(V, 4)).astype(np.int32),
        skin_weights=w,
        clips={"c": Clip("c", 30.0, q, np.zeros((T, J, 3), np.float32), np.ones((T, J, 3), np.float32))},
    )


def checksum(asset: RiggedAsset) -> str:
    return f"{float(asset.vertices.sum()):.6e}"


def main() -> None:
    root, prefix, count = Path(sys.argv[1]), sys.argv[2], int(sys.argv[3])
    bank = Bank(root)
    print("READY", flush=True)
    for i in range(count):
        a = synthetic(
            f"{prefix}{i:03d}", seed=zlib.crc32(prefix.encode()) % 1000 + i
        )  # same name, same content
        bank.add(a, replace=True)
        print(f"ADDED {a.name} {checksum(a)}", flush=True)


if __name__ == "__main__":
    main()
