"""`PCAPrior`: the per-skeleton Gaussian/PCA baseline as a motion prior (``pca`` plugin) that
`zooctl motion train --kind pca` trains and `zooctl animate` samples like any other.

Per skeleton, a Gaussian over the top principal components of flattened 6D windows of
``length`` frames (`baselines.PCABaseline`); longer motions chain windows, cross-fading the
``overlap`` frames they share. A skeleton it never saw uses the trained skeleton with the same
joint count and the nearest rest pose.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..asset import RiggedAsset
from ..errors import InputError, StoreError
from ..geometry import matrix_to_quat
from .baselines import PCABaseline, rot6d_to_matrix_np
from .dataset import MotionSequence, quat_mul, resample, windows
from .skeleton import Skeleton

FILE = "pca.npz"


class PCAPrior:
    plugin = "pca"

    def __init__(
        self, length: int = 30, components: int = 32, fps: float = 30.0, device: str = "cpu", **_: Any
    ):
        if length < 4 or components < 1:
            raise InputError(
                f"the PCA prior needs length >= 4 and components >= 1, got {length}, {components}"
            )
        self.length, self.components, self.fps = int(length), int(components), float(fps)
        self.models: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = {}
        self.training: dict[str, Any] = {}

    def fit(self, sequences: Sequence[MotionSequence]) -> None:
        """Fit one Gaussian per skeleton on the windows of ``sequences``."""
        base = PCABaseline(self.components)
        names = []
        for s in sequences:
            w = windows(resample(s, self.fps), self.length, max(1, self.length // 2))
            if len(w):
                base.add(s.skeleton, w)
                names.append(s.name)
        if not base.windows:
            raise InputError(
                f"no motion windows of {self.length} frames to fit the PCA prior on",
                hint="train on longer clips, or with a shorter --length",
            )
        for key, sk in base.skeletons.items():
            mean, basis, std, _ = base._model(key)
            self.models[key] = (sk.rest_positions, mean, basis, std)
        self.training.update({"sequences": names, "skeletons": sorted(self.models)})

    def _key(self, sk: Skeleton) -> str:
        if sk.key in self.models:
            return sk.key
        same = [k for k, m in self.models.items() if m[0].shape == sk.rest_positions.shape]
        if not same:
            raise InputError(f"the PCA prior has no training data for a {sk.num_joints}-joint skeleton")
        return min(same, key=lambda k: float(np.abs(self.models[k][0] - sk.rest_positions).sum()))

    def sample_delta(self, sk: Skeleton, n: int, frames: int, seed: int = 0) -> np.ndarray:
        """(n, frames, J, 4) rest-relative rotations, windows chained with cross-fades."""
        _, mean, basis, std = self.models[self._key(sk)]
        L, J = self.length, sk.num_joints
        ov = max(1, L // 4)
        K = 1 if frames <= L else int(np.ceil((frames - ov) / (L - ov)))
        rng = np.random.default_rng(seed)
        x = (mean + (rng.standard_normal((n * K, len(std))) * std) @ basis).reshape(n, K, L, J, 6)
        out = x[:, 0]
        w = np.linspace(0.0, 1.0, ov + 2)[1:-1, None, None]  # cross-fade weights over the overlap
        for k in range(1, K):
            blend = (1 - w) * out[:, -ov:] + w * x[:, k, :ov]
            out = np.concatenate([out[:, :-ov], blend, x[:, k, ov:]], 1)
        return matrix_to_quat(rot6d_to_matrix_np(out[:, :frames]))

    def sample(
        self, asset: RiggedAsset | Skeleton, n: int = 5, frames: int = 60, seed: int = 0, **_: Any
    ) -> np.ndarray:
        """(n, frames, J, 4) wxyz local rotations for ``asset`` (a `RiggedAsset` or a `Skeleton`)."""
        sk = asset if isinstance(asset, Skeleton) else Skeleton.from_asset(asset)
        return quat_mul(sk.rest_rotations[None, None], self.sample_delta(sk, n, frames, seed))

    # -- persistence ----------------------------------------------------------------------------
    def save(self, directory: str | Path, name: str | None = None, extra: dict | None = None) -> None:
        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        keys = sorted(self.models)
        arrays = {
            f"{part}_{i}": a
            for i, k in enumerate(keys)
            for part, a in zip(("rest", "mean", "basis", "std"), self.models[k], strict=True)
        }
        with open(d / FILE, "wb") as fh:
            np.savez(fh, keys=np.array(keys), **arrays)
        cfg = {
            "schema_version": 1,
            "name": name or d.name,
            "plugin": self.plugin,
            "model": {"length": self.length, "components": self.components, "fps": self.fps},
            "parameters": int(sum(m[1].size + m[2].size + m[3].size for m in self.models.values())),
            "training": dict(self.training),
            "files": {"model": FILE},
            **(extra or {}),
        }
        (d / "config.json").write_text(json.dumps(cfg, indent=1, sort_keys=True) + "\n")

    @classmethod
    def load(cls, directory: str | Path, device: str = "cpu") -> PCAPrior:
        d = Path(directory)
        try:
            cfg = json.loads((d / "config.json").read_text())
            prior = cls(
                **{k: v for k, v in cfg.get("model", {}).items() if k in ("length", "components", "fps")}
            )
            with np.load(d / FILE, allow_pickle=False) as z:
                for i, k in enumerate(z["keys"].tolist()):
                    prior.models[k] = tuple(z[f"{p}_{i}"] for p in ("rest", "mean", "basis", "std"))
        except (OSError, KeyError, ValueError, json.JSONDecodeError) as exc:
            raise StoreError(
                f"the PCA motion prior at {d} is unreadable: {exc}", hint="train it again"
            ) from None
        prior.training = cfg.get("training", {})
        return prior
