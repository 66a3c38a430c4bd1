"""`PonymationPrior`: the trained motion VAE as a motion-prior component (``ponymation`` plugin).

Interface of every motion prior (see `zooctl.hookspecs.register_motion_priors`): ``fit(sequences)``,
``save(directory)``, ``sample(asset, n, frames, seed) -> (n, frames, J, 4)`` local rotations (wxyz),
plus ``load(directory)`` as a classmethod.

Long motions (Ponymation appendix A): the VAE decodes ``length``-frame segments. For more frames,
K independent *content* segments are sampled, and between each pair a *transition* segment whose
latent is optimised so that it starts where the previous segment ends and ends where the next one
starts (poses and velocities, on joint positions and rotations), with a Gaussian prior on the
latent. The output is c_0, t_0 (without its two end frames, which duplicate the neighbours), c_1, ...
"""

from __future__ import annotations

import json
import pickle
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..asset import Clip
from ..errors import InputError, StoreError
from ..geometry import decompose_trs, matrix_to_quat
from .dataset import MotionDataset, MotionSequence, quat_mul
from .model import MotionConfig, MotionVAE
from .skeleton import Skeleton, SkeletonBatch
from .train import TrainHistory, TrainOptions, train_vae

WEIGHTS = "weights.pt"
CONFIG = "config.json"
SCHEMA_VERSION = 1


class PonymationPrior:
    """A spatio-temporal transformer VAE over per-bone rotations, for any skeleton."""

    plugin = "ponymation"

    def __init__(self, config: MotionConfig | dict | None = None, device: str = "cpu", **options: Any):
        if isinstance(config, dict):
            config = MotionConfig.from_json(config)
        self.cfg = config or MotionConfig(**options)
        self.device = torch.device(device)
        self.model = MotionVAE(self.cfg).to(self.device).eval()
        self.training: dict[str, Any] = {}
        self.history: TrainHistory | None = None

    # -- training ---------------------------------------------------------------------------
    def dataset(
        self, sequences: Sequence[MotionSequence], speeds: Sequence[float] = (0.8, 1.25)
    ) -> MotionDataset:
        return MotionDataset(sequences, length=self.cfg.length, fps=self.cfg.fps, speeds=speeds)

    def fit(
        self,
        data: Sequence[MotionSequence] | MotionDataset,
        options: TrainOptions | None = None,
        on_step: Callable[[int, int, dict[str, float]], None] | None = None,
    ) -> TrainHistory:
        """Train on sequences (or a prepared `MotionDataset`); records what it trained on."""
        ds = data if isinstance(data, MotionDataset) else self.dataset(data)
        opts = options or TrainOptions(device=str(self.device))
        self.history = train_vae(self.model, ds, opts, on_step)
        self.model.to(self.device).eval()
        self.training.update(
            {
                "sequences": ds.sequence_names,
                "skeletons": sorted({s.key for s in ds.skeletons}),
                "windows": len(ds),
                "frames": ds.num_frames,
                "epochs": self.history.epochs,
                "steps": self.history.steps,
                "seconds": round(self.history.seconds, 2),
                "stopped_early": self.history.stopped_early,
                "batch_size": opts.batch_size,
                "lr": opts.lr,
                "device": str(opts.device),
                "final_loss": self.history.to_json()["final"],
            }
        )
        return self.history

    # -- persistence --------------------------------------------------------------------------
    def config_json(self, name: str, extra: dict[str, Any] | None = None) -> dict[str, Any]:
        """The ``config.json`` of this prior (schema: ``schemas/motion_prior.schema.json``)."""
        out = {
            "schema_version": SCHEMA_VERSION,
            "name": name,
            "plugin": self.plugin,
            "model": self.cfg.to_json(),
            "parameters": sum(p.numel() for p in self.model.parameters()),
            "training": dict(self.training),
            "files": {"weights": WEIGHTS},
        }
        out.update(extra or {})
        return out

    def save(
        self, directory: str | Path, name: str | None = None, extra: dict[str, Any] | None = None
    ) -> None:
        """Write ``weights.pt`` and ``config.json`` into ``directory`` (the caller publishes it)."""
        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        torch.save({k: v.detach().cpu() for k, v in self.model.state_dict().items()}, d / WEIGHTS)
        cfg = self.config_json(name or d.name, extra)
        (d / CONFIG).write_text(json.dumps(cfg, indent=1, sort_keys=True) + "\n")

    @classmethod
    def load(cls, directory: str | Path, device: str = "cpu") -> PonymationPrior:
        d = Path(directory)
        try:
            cfg = json.loads((d / CONFIG).read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise StoreError(f"the motion prior at {d} is unreadable: {exc}", hint="train it again") from None
        if cfg.get("schema_version") != SCHEMA_VERSION:
            raise StoreError(
                f"motion prior {d.name!r} has schema version {cfg.get('schema_version')}, "
                f"this zooctl reads {SCHEMA_VERSION}",
                hint="train it again",
            )
        prior = cls(MotionConfig.from_json(cfg.get("model", {})), device=device)
        try:
            state = torch.load(
                d / cfg.get("files", {}).get("weights", WEIGHTS), map_location="cpu", weights_only=True
            )
            prior.model.load_state_dict(state)
        except (OSError, RuntimeError, EOFError, pickle.UnpicklingError) as exc:
            msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise StoreError(
                f"the weights of motion prior {d.name!r} are unreadable: {msg}", hint="train it again"
            ) from None
        prior.model.to(prior.device).eval()
        prior.training = cfg.get("training", {})
        return prior

    # -- sampling -----------------------------------------------------------------------------
    def _skeletons(self, skeleton: Skeleton, n: int) -> SkeletonBatch:
        return SkeletonBatch([skeleton], device=self.device).take([0] * n)

    @torch.no_grad()
    def reconstruct(self, windows: np.ndarray, skeleton: Skeleton) -> np.ndarray:
        """Encode and decode (posterior mean) windows (N, T, J, 4) of rest-relative rotations."""
        from ..geometry import quat_to_matrix
        from .dataset import matrix_to_rot6d

        if len(windows) == 0:
            return windows.copy()
        x = torch.as_tensor(matrix_to_rot6d(quat_to_matrix(windows)), dtype=torch.float32, device=self.device)
        sk = self._skeletons(skeleton, len(windows))
        pred, _, _ = self.model(x, sk, sample=False)
        return self._to_quat(pred)

    def sample_delta(
        self, skeleton: Skeleton, n: int, frames: int, seed: int = 0, transition_steps: int = 30
    ) -> np.ndarray:
        """(n, frames, J, 4) rotations relative to rest, chained with optimised transitions."""
        if n < 1 or frames < 1:
            raise InputError(f"need at least one sample of one frame, got n={n}, frames={frames}")
        L, Z = self.cfg.length, self.cfg.latent
        gen = torch.Generator().manual_seed(int(seed))
        K = 1 if frames <= L else int(np.ceil((frames + L - 2) / (2 * L - 2)))
        z_content = torch.randn(n * K, Z, generator=gen).to(self.device)
        with torch.no_grad():
            content = self.model.decode(z_content, self._skeletons(skeleton, n * K), L).reshape(
                n, K, L, -1, 6
            )
        if K == 1:
            return self._to_quat(content[:, 0, :frames])
        z_trans = torch.randn(n * (K - 1), Z, generator=gen).to(self.device)
        z_trans = self._optimise_transitions(z_trans, content, skeleton, transition_steps)
        with torch.no_grad():
            trans = self.model.decode(z_trans, self._skeletons(skeleton, n * (K - 1)), L).reshape(
                n, K - 1, L, -1, 6
            )
        parts = [content[:, 0]]
        for k in range(K - 1):
            parts += [trans[:, k, 1 : L - 1], content[:, k + 1]]
        return self._to_quat(torch.cat(parts, 1)[:, :frames])

    def _optimise_transitions(
        self, z: torch.Tensor, content: torch.Tensor, skeleton: Skeleton, steps: int
    ) -> torch.Tensor:
        """Optimise transition latents z (n*(K-1), Z) against content (n, K, L, J, 6)."""
        from ..rig.rotations import rot6d_to_matrix

        n, K, L = content.shape[:3]
        sk = self._skeletons(skeleton, n * (K - 1))
        mask = sk.mask[:, None, :, None]
        # Targets: the last two frames of segment k and the first two of segment k + 1.
        ends = torch.cat([content[:, :-1, L - 2 :], content[:, 1:, :2]], 2).reshape(n * (K - 1), 4, -1, 6)
        target_rot = rot6d_to_matrix(ends)
        with torch.no_grad():
            target_pos = sk.joint_positions(target_rot)
        pick = torch.tensor([0, 1, L - 2, L - 1], device=self.device)
        z = z.clone().requires_grad_(True)
        opt = torch.optim.Adam([z], lr=0.05)
        for p in self.model.parameters():
            p.requires_grad_(False)
        try:
            for _ in range(steps):
                frames = self.model.decode_frames(z, L)[:, pick]  # only the 4 boundary frames need bones
                rot = rot6d_to_matrix(self.model.decode_bones(frames, sk))
                pos = sk.joint_positions(rot)
                # Pose at both ends: t[0] = c_k[-1], t[-1] = c_{k+1}[0]; velocity at both ends too.
                pose_err = (pos[:, [0, 3]] - target_pos[:, [1, 2]]) ** 2
                vel_err = ((pos[:, 1] - pos[:, 0]) - (target_pos[:, 1] - target_pos[:, 0])) ** 2
                vel_err2 = ((pos[:, 3] - pos[:, 2]) - (target_pos[:, 3] - target_pos[:, 2])) ** 2
                rot_err = (rot[:, [0, 3]] - target_rot[:, [1, 2]]) ** 2
                loss = (
                    (pose_err * mask).sum()
                    + ((vel_err + vel_err2) * mask[:, 0]).sum()
                    + 0.1 * (rot_err * mask[..., None]).sum()
                ) / mask.sum() + 1e-3 * (z**2).mean()
                opt.zero_grad()
                loss.backward()
                opt.step()
        finally:
            for p in self.model.parameters():
                p.requires_grad_(True)
        return z.detach()

    def sample(self, asset: Any, n: int = 5, frames: int = 60, seed: int = 0, **options: Any) -> np.ndarray:
        """(n, frames, J, 4) wxyz local rotations for ``asset`` (a `RiggedAsset` or a `Skeleton`)."""
        sk = asset if isinstance(asset, Skeleton) else Skeleton.from_asset(asset)
        delta = self.sample_delta(sk, n, frames, seed, **options)
        return quat_mul(sk.rest_rotations[None, None], delta)

    def _to_quat(self, rot6d: torch.Tensor) -> np.ndarray:
        from ..rig.rotations import rot6d_to_matrix

        return matrix_to_quat(rot6d_to_matrix(rot6d.detach().double()).cpu().numpy())


def motion_clip(asset: Any, rotations: np.ndarray, fps: float, name: str) -> Clip:
    """A `Clip` of ``asset`` with the given local rotations (T, J, 4) and every joint at its rest
    translation and scale (root motion is not modelled)."""
    t, _, s = decompose_trs(asset.rest_local)
    T = len(rotations)
    return Clip(
        name,
        float(fps),
        np.asarray(rotations, dtype=np.float64),
        np.repeat(t[None], T, 0),
        np.repeat(s[None], T, 0),
    )
