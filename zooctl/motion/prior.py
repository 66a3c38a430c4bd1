"""`PonymationPrior`: the trained motion VAE as a motion-prior component (``ponymation`` plugin).

Interface of every motion prior (see `zooctl.hookspecs.register_motion_priors`): ``fit(sequences)``,
``save(directory)``, ``sample(asset, n, frames, seed) -> (n, frames, J, 4)`` local rotations (wxyz),
plus ``load(directory)`` as a classmethod; optionally ``sequence_prior(asset, video_fps)``, a prior
on a fit's rotations (the fit's ``motion`` pose prior; `zooctl.motion.fit_prior`).

Long motions (Ponymation appendix A): the VAE decodes ``length``-frame segments. For more frames,
K independent *content* segments are sampled, and between each pair a *transition* segment whose
latent is optimised so that it starts where the previous segment ends and ends where the next one
starts (poses and velocities, matched on the temporal decoder's frame features, which the spatial
decoder turns into poses), with a Gaussian prior on the latent. The output is c_0, t_0 (without
its two end frames, which duplicate the neighbours), c_1, ...; the spatial decoder runs once over
the kept frames.
"""

from __future__ import annotations

import io
import json
import pickle
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from ..asset import Clip, RiggedAsset
from ..errors import InputError, StoreError
from ..geometry import decompose_trs, matrix_to_quat
from .calibrate import calibrate_temperature
from .dataset import MotionDataset, MotionSequence, quat_mul
from .latents import LatentGaussians
from .model import MotionConfig, build_model
from .skeleton import Skeleton, SkeletonBatch
from .temperature import default_temperature, draws_diversely
from .train import TrainHistory, TrainOptions, train_vae

if TYPE_CHECKING:
    from .fit_prior import SequencePrior

WEIGHTS = "weights.pt"
CONFIG = "config.json"
LATENTS = "latents.npz"
SCHEMA_VERSION = 1


class PonymationPrior:
    """A spatio-temporal transformer VAE over per-bone rotations, for any skeleton."""

    plugin = "ponymation"

    def __init__(self, config: MotionConfig | dict | None = None, device: str = "cpu", **options: Any):
        if isinstance(config, dict):
            config = MotionConfig.from_json(config)
        self.cfg = config or MotionConfig(**options)
        self.device = torch.device(device)
        self.model = build_model(self.cfg).to(self.device).eval()
        self.training: dict[str, Any] = {}
        self.history: TrainHistory | None = None
        self.latents: LatentGaussians | None = None  # aggregate posterior (`latents`), set by `fit`

    # -- training ---------------------------------------------------------------------------
    def dataset(
        self, sequences: Sequence[MotionSequence], speeds: Sequence[float] = (0.8, 1.25)
    ) -> MotionDataset:
        if self.cfg.mirror:
            from .mirror import mirror_sequence

            mirrored = [m for m in (mirror_sequence(s) for s in sequences) if m is not None]
            sequences = [*sequences, *mirrored]
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
                "max_minutes": opts.max_minutes,
                "max_steps": opts.max_steps,
                "recon_warmup": opts.recon_warmup,
                "kl_anneal": opts.kl_anneal,
                "device": str(opts.device),
                "final_loss": self.history.to_json()["final"],
            }
        )
        self.latents = LatentGaussians.fit(self.model, ds) if self.cfg.sampler != "normal" else None
        if draws_diversely(self.cfg.to_json()):
            self.training["sample_temperature"] = 1.0
        else:
            cal = calibrate_temperature(self, ds)
            self.training["sample_temperature"] = cal["temperature"]
            self.training["calibration"] = cal
        return self.history

    @property
    def sample_temperature(self) -> float:
        """Default sampling temperature (`default_temperature`)."""
        return default_temperature(self.cfg.to_json(), self.training)

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
        # Into memory first: torch.save to a file on a full disk raises a RuntimeError, not an OSError.
        buf = io.BytesIO()
        torch.save({k: v.detach().cpu() for k, v in self.model.state_dict().items()}, buf)
        (d / WEIGHTS).write_bytes(buf.getvalue())
        cfg = self.config_json(name or d.name, extra)
        if self.latents is not None:
            self.latents.save(d / LATENTS)
            cfg["files"] = {**cfg["files"], "latents": LATENTS}
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
        if "latents" in cfg.get("files", {}):
            try:
                prior.latents = LatentGaussians.load(d / cfg["files"]["latents"])
            except (OSError, KeyError, ValueError) as exc:
                raise StoreError(
                    f"the latent statistics of motion prior {d.name!r} are unreadable: {exc}",
                    hint="train it again",
                ) from None
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

    def sequence_prior(self, asset: RiggedAsset, video_fps: float) -> SequencePrior:
        """The VAE as a prior on a fit's rotations of ``asset`` (`zooctl.motion.fit_prior`)."""
        from .fit_prior import SequencePrior

        return SequencePrior(self.model, self.cfg, asset, video_fps, self.device)

    def sample_delta(
        self,
        skeleton: Skeleton,
        n: int,
        frames: int,
        seed: int = 0,
        transition_steps: int = 10,
        temperature: float | None = None,
    ) -> np.ndarray:
        """(n, frames, J, 4) rotations relative to rest, chained with optimised transitions.

        ``temperature`` scales the prior's standard deviation (z ~ N(0, temperature^2 I)); default:
        the prior's `sample_temperature`.
        """
        temperature = self.sample_temperature if temperature is None else temperature
        if n < 1 or frames < 1:
            raise InputError(f"need at least one sample of one frame, got n={n}, frames={frames}")
        if not temperature >= 0:
            raise InputError(f"temperature must be >= 0, got {temperature}")
        L = self.cfg.length
        gen = torch.Generator().manual_seed(int(seed))
        K = 1 if frames <= L else int(np.ceil((frames + L - 2) / (2 * L - 2)))
        # The samples' first segments are drawn together (different actions when `diverse`); the
        # segments that continue them one by one, so a sample does not leap between extremes.
        z_content = self._draw(skeleton, n, temperature, gen, diverse=self.cfg.diverse)[:, None]
        if K > 1:
            z_next = self._draw(skeleton, n * (K - 1), temperature, gen).reshape(n, K - 1, -1)
            z_content = torch.cat([z_content, z_next], 1)
        z_content = z_content.reshape(n * K, -1)
        with torch.no_grad():
            content = self.model.frame_features(z_content, self._skeletons(skeleton, n * K))
            content = content.reshape(n, K, L, -1)  # (n, K, L, W)
        feats = content[:, 0]
        if K > 1:
            z_trans = self._draw(skeleton, n * (K - 1), temperature, gen)
            sk_t = self._skeletons(skeleton, n * (K - 1))
            z_trans = self._optimise_transitions(z_trans, content, transition_steps, sk_t)
            trans = self._transition_frames(z_trans, content, sk_t)  # (n, K-1, L, W)
            parts = [content[:, 0]]
            for k in range(K - 1):
                parts += [trans[:, k, 1 : L - 1], content[:, k + 1]]
            feats = torch.cat(parts, 1)
        # One spatial decode for every kept frame: it costs T * J tokens, the bulk of sampling.
        with torch.no_grad():
            rot = self.model.features_to_rot6d(feats[:, :frames], self._skeletons(skeleton, n))
        q = self._to_quat(rot)
        return q if self.latents is None else self.latents.limit_rotations(skeleton, q)

    def _draw(
        self, skeleton: Skeleton, n: int, temperature: float, gen: torch.Generator, diverse: bool = False
    ) -> torch.Tensor:
        """(n, Z) latents: from the skeleton's aggregate posterior when the prior has one, else
        from N(0, temperature^2 I); ``diverse``: see `latents.LatentGaussians.sample`."""
        if self.latents is not None:
            mixture = self.cfg.sampler == "mixture"
            z = self.latents.sample(
                skeleton,
                n,
                temperature,
                gen,
                mixture,
                donors=self.cfg.donors,
                donor_share=self.cfg.donor_share,
                diverse=diverse,
            )
            return z.to(self.device)
        return (torch.randn(n, self.cfg.latent, generator=gen) * temperature).to(self.device)

    def seams(self, frames: int) -> list[int]:
        """Frames of a ``frames``-long sample where a new segment starts (content, transition,
        content, ...): where chaining could show."""
        L, out, t, k = self.cfg.length, [], self.cfg.length, 0
        while t < frames:
            out.append(t)
            t += L - 2 if k % 2 == 0 else L
            k += 1
        return out

    @staticmethod
    def _ends(content: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """content (n, K, L, W) -> the segments before and after each transition, (n*(K-1), L, W) each."""
        n, K, L, W = content.shape
        return content[:, :-1].reshape(-1, L, W), content[:, 1:].reshape(-1, L, W)

    def _optimise_transitions(
        self, z: torch.Tensor, content: torch.Tensor, steps: int, sk: SkeletonBatch
    ) -> torch.Tensor:
        """Transition latents (Ponymation appendix A): z (n*(K-1), Z) initial latents, content
        (n, K, L, W) frame features of the content segments -> optimised z.

        The objective lives in the decoder's *frame-feature* space: the spatial decoder maps equal
        features to equal poses, so matching the features of the boundary frames (and their
        differences, for velocity) matches the poses without running the J-token spatial decoder in
        the loop (which made this step slow on big skeletons; BENCHMARKS.md, "Measurements behind
        code choices").
        """
        prev, nxt = self._ends(content)
        scale = content.reshape(-1, content.shape[-1]).var(0).mean().clamp_min(1e-8)  # scale-free loss
        z = z.detach().clone().requires_grad_(True)
        if steps <= 0:
            return z.detach()
        # Adam by hand: `torch.optim` imports torch._dynamo on first use, seconds of a fresh process.
        m, v, lr, b1, b2 = torch.zeros_like(z), torch.zeros_like(z), 0.1, 0.9, 0.999
        for p in self.model.parameters():
            p.requires_grad_(False)
        try:
            for i in range(1, steps + 1):
                loss = transition_error(self.model.frame_features(z, sk), prev, nxt).mean() / scale
                loss = loss + 1e-3 * (z**2).mean()  # the Gaussian prior keeps z plausible
                (g,) = torch.autograd.grad(loss, z)
                with torch.no_grad():
                    m.mul_(b1).add_(g, alpha=1 - b1)
                    v.mul_(b2).addcmul_(g, g, value=1 - b2)
                    step = lr * (m / (1 - b1**i)) / ((v / (1 - b2**i)).sqrt() + 1e-8)
                    z -= step
        finally:
            for p in self.model.parameters():
                p.requires_grad_(True)
        return z.detach()

    @torch.no_grad()
    def _transition_frames(self, z: torch.Tensor, content: torch.Tensor, sk: SkeletonBatch) -> torch.Tensor:
        """Decoded transition features (n, K-1, L, W) for latents z (n*(K-1), Z). What is left of
        the mismatch at both ends, in position and in velocity, is removed by a cubic Hermite
        correction, so segments join exactly and without a kink (a linear correction left a
        velocity jump at every seam)."""
        n, K, L, W = content.shape
        prev, nxt = self._ends(content)
        t = self.model.frame_features(z, sk)
        dp0, dp1 = prev[:, -1:] - t[:, :1], nxt[:, :1] - t[:, -1:]
        dv0 = (prev[:, -1:] - prev[:, -2:-1]) - (t[:, 1:2] - t[:, :1])
        dv1 = (nxt[:, 1:2] - nxt[:, :1]) - (t[:, -1:] - t[:, -2:-1])
        s = torch.linspace(0.0, 1.0, L, device=t.device)[None, :, None]
        h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
        h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
        t = t + h00 * dp0 + h01 * dp1 + (L - 1) * (h10 * dv0 + h11 * dv1)
        return t.reshape(n, K - 1, L, W)

    def sample(
        self, asset: RiggedAsset | Skeleton, n: int = 5, frames: int = 60, seed: int = 0, **options: Any
    ) -> np.ndarray:
        """(n, frames, J, 4) wxyz local rotations for ``asset`` (a `RiggedAsset` or a `Skeleton`)."""
        sk = asset if isinstance(asset, Skeleton) else Skeleton.from_asset(asset)
        delta = self.sample_delta(sk, n, frames, seed, **options)
        return quat_mul(sk.rest_rotations[None, None], delta)

    def _to_quat(self, rot6d: torch.Tensor) -> np.ndarray:
        from ..rig.rotations import rot6d_to_matrix

        return matrix_to_quat(rot6d_to_matrix(rot6d.detach().double()).cpu().numpy())


def transition_error(t: torch.Tensor, prev: torch.Tensor, nxt: torch.Tensor) -> torch.Tensor:
    """How badly transition frames t (N, L, W) join prev and nxt (N, L, W): squared feature error
    of t[0] against prev[-1] and t[-1] against nxt[0], and of the velocities at both ends -> (N,)."""
    err = (
        (t[:, 0] - prev[:, -1]) ** 2
        + (t[:, -1] - nxt[:, 0]) ** 2
        + ((t[:, 1] - t[:, 0]) - (prev[:, -1] - prev[:, -2])) ** 2
        + ((t[:, -1] - t[:, -2]) - (nxt[:, 1] - nxt[:, 0])) ** 2
    )
    return err.mean(-1)


def motion_clip(asset: RiggedAsset, rotations: np.ndarray, fps: float, name: str) -> Clip:
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
