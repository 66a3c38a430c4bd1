"""An example third-party motion prior, ``example-loop``: replays the training clips of the same
skeleton from a random frame at a random speed (0.8-1.25), looping, which is what a plugin needs
to implement (`zooctl.hookspecs.register_motion_priors`): ``fit(sequences)``, ``save(directory)``,
``load(directory)`` and ``sample(asset, n, frames, seed) -> (n, frames, J, 4)`` local rotations.

`zooctl motion train --kind example-loop --all` trains it, `zooctl animate X --prior NAME`
samples it. Register this module as its own entry point (``[project.entry-points.zooctl]``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from zooctl.components import ComponentSpec
from zooctl.errors import InputError, StoreError
from zooctl.plugins import hookimpl

FILE = "clips.npz"


class LoopPrior:
    plugin = "example-loop"

    def __init__(self, device: str = "cpu", **_: Any):
        self.clips: dict[str, list[np.ndarray]] = {}  # skeleton key -> rest-relative (T, J, 4) each
        self.training: dict[str, Any] = {}

    def fit(self, sequences) -> None:
        for s in sequences:
            if s.num_frames >= 2:
                self.clips.setdefault(s.skeleton.key, []).append(np.asarray(s.rotations, np.float64))
        if not self.clips:
            raise InputError("example-loop: no clip of two frames or more to learn from")
        self.training = {"sequences": [s.name for s in sequences], "skeletons": sorted(self.clips)}

    def sample(self, asset: Any, n: int = 5, frames: int = 60, seed: int = 0, **_: Any) -> np.ndarray:
        from zooctl.geometry import quat_mul, quat_slerp
        from zooctl.motion.skeleton import Skeleton

        sk = asset if isinstance(asset, Skeleton) else Skeleton.from_asset(asset)
        pool = self.clips.get(sk.key) or [
            c for cs in self.clips.values() for c in cs if c.shape[1] == sk.num_joints
        ]
        if not pool:
            raise InputError(f"example-loop has no clip for a {sk.num_joints}-joint skeleton")
        rng = np.random.default_rng(seed)
        out = np.empty((n, frames, sk.num_joints, 4))
        for i in range(n):
            clip = pool[rng.integers(len(pool))]
            t = (rng.uniform(0, len(clip)) + rng.uniform(0.8, 1.25) * np.arange(frames)) % (len(clip) - 1)
            i0 = np.floor(t).astype(int)
            w = np.broadcast_to((t - i0)[:, None], (frames, sk.num_joints))
            out[i] = quat_slerp(clip[i0], clip[i0 + 1], w)
        return quat_mul(sk.rest_rotations[None, None], out)

    def save(self, directory: str | Path) -> None:
        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        arrays = {f"{k}|{i}": c for k, cs in self.clips.items() for i, c in enumerate(cs)}
        with open(d / FILE, "wb") as fh:
            np.savez(fh, **arrays)
        cfg = {
            "schema_version": 1,
            "plugin": self.plugin,
            "training": self.training,
            "files": {"clips": FILE},
        }
        (d / "config.json").write_text(json.dumps(cfg, indent=1) + "\n")

    @classmethod
    def load(cls, directory: str | Path, device: str = "cpu") -> LoopPrior:
        prior = cls()
        try:
            with np.load(Path(directory) / FILE, allow_pickle=False) as z:
                for name in z.files:
                    prior.clips.setdefault(name.rsplit("|", 1)[0], []).append(z[name])
        except (OSError, ValueError) as exc:
            raise StoreError(f"example-loop prior at {directory} is unreadable: {exc}") from None
        return prior


def _factory(path: Any = None, device: str = "cpu", **options: Any) -> LoopPrior:
    return LoopPrior.load(path, device) if path is not None else LoopPrior(device, **options)


@hookimpl
def register_motion_priors(register):
    register(ComponentSpec("motion_prior", "example-loop", _factory, "replays training clips, looped"))
