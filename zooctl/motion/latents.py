"""Where the trained VAE's latents live: one Gaussian per skeleton fitted to the posterior means
of its training windows (the *aggregate posterior*), sampled instead of N(0, I).

With enough information in z to reconstruct motion (not just the window's mean pose), the
posteriors fill only a small, skeleton-dependent part of N(0, I): a draw from N(0, I) decodes
to something between every skeleton's motions, a still pose. Drawing from the Gaussian of the
skeleton's own posteriors decodes to motions like its clips, and new ones where the Gaussian
interpolates between them. A skeleton the prior never saw uses its nearest trained skeleton
(same joint count, nearest rest pose), else the Gaussian of every window.

Shapes: Z latent size; ``mean`` (Z,), ``factor`` (Z, Z) with ``factor @ factor.T`` the covariance.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from .skeleton import Skeleton

ALL = "*"  # key of the pooled Gaussian


class LatentGaussians:
    def __init__(self) -> None:
        self.mean: dict[str, np.ndarray] = {}
        self.factor: dict[str, np.ndarray] = {}
        self.rest: dict[str, np.ndarray] = {}  # normalised rest joint positions (J, 3) per key

    def __len__(self) -> int:
        return len(self.mean)

    @staticmethod
    def _gaussian(mu: np.ndarray, ridge: float = 1e-4) -> tuple[np.ndarray, np.ndarray]:
        """mu (N, Z) -> (mean (Z,), factor (Z, Z)); a small ridge keeps the factor defined for
        fewer windows than latent dimensions."""
        m = mu.mean(0)
        c = np.cov(mu - m, rowvar=False) if len(mu) > 1 else np.zeros((mu.shape[1],) * 2)
        c = np.atleast_2d(c) + ridge * np.eye(mu.shape[1])
        return m, np.linalg.cholesky(c)

    @classmethod
    @torch.no_grad()
    def fit(cls, model, dataset, batch_size: int = 256) -> LatentGaussians:
        """Posterior means of every window of ``dataset`` (a `MotionDataset`) under ``model``."""
        dev = next(model.parameters()).device
        mus = []
        for s in range(0, len(dataset), batch_size):
            b = dataset.batch(np.arange(s, min(len(dataset), s + batch_size)), dev)
            mus.append(model.encode(b.rot6d, b.skeletons)[0].double().cpu().numpy())
        mu = np.concatenate(mus)
        out = cls()
        ids = np.asarray(dataset.skel_ids)
        for sid, sk in enumerate(dataset.skeletons):
            sel = mu[ids == sid]
            if len(sel):
                out.mean[sk.key], out.factor[sk.key] = cls._gaussian(sel)
                out.rest[sk.key] = sk.rest_positions
        out.mean[ALL], out.factor[ALL] = cls._gaussian(mu)
        return out

    def key_for(self, skeleton: Skeleton) -> str:
        """The trained skeleton to sample for ``skeleton``: itself, the nearest of the same joint
        count, or the pooled Gaussian."""
        if skeleton.key in self.mean:
            return skeleton.key
        same = [k for k, r in self.rest.items() if r.shape == skeleton.rest_positions.shape]
        if not same:
            return ALL
        return min(same, key=lambda k: float(np.abs(self.rest[k] - skeleton.rest_positions).sum()))

    def sample(self, skeleton: Skeleton, n: int, temperature: float, gen: torch.Generator) -> torch.Tensor:
        """(n, Z) latents; ``temperature`` scales the spread around the skeleton's mean latent."""
        k = self.key_for(skeleton)
        m = torch.as_tensor(self.mean[k], dtype=torch.float32)
        f = torch.as_tensor(self.factor[k], dtype=torch.float32)
        eps = torch.randn(n, len(m), generator=gen)
        return m + temperature * eps @ f.T

    # -- persistence ------------------------------------------------------------------------
    def save(self, path: str | Path) -> None:
        arrays = {}
        for i, k in enumerate(self.mean):
            arrays[f"mean_{i}"], arrays[f"factor_{i}"] = self.mean[k], self.factor[k]
            if k in self.rest:
                arrays[f"rest_{i}"] = self.rest[k]
        keys = np.array(list(self.mean), dtype=object)
        with open(path, "wb") as fh:
            np.savez(fh, keys=np.array([str(k) for k in keys]), **arrays)

    @classmethod
    def load(cls, path: str | Path) -> LatentGaussians:
        out = cls()
        with np.load(path, allow_pickle=False) as z:
            for i, k in enumerate(z["keys"].tolist()):
                out.mean[k], out.factor[k] = z[f"mean_{i}"], z[f"factor_{i}"]
                if f"rest_{i}" in z:
                    out.rest[k] = z[f"rest_{i}"]
        return out
