"""Where the trained VAE's latents live: one Gaussian per skeleton fitted to the posterior means
of its training windows (the *aggregate posterior*), sampled instead of N(0, I).

With enough information in z to reconstruct motion (not just the window's mean pose), the
posteriors fill only a small, skeleton-dependent part of N(0, I): a draw from N(0, I) decodes
to something between every skeleton's motions, a still pose. Drawing from the Gaussian of the
skeleton's own posteriors decodes to motions like its clips, and new ones where the Gaussian
interpolates between them. A skeleton the prior never saw uses its nearest trained skeleton
(same joint count, nearest rest pose), else the Gaussian of every window.

Mixture sampling also borrows from *donors*: the trained skeletons whose window latents lie
closest to this skeleton's (`donors_of`). The encoder puts animals of one body plan in the same
region (the horse's nearest are the deer, alpaca and cow; the koi's other fish; the T-rex the
other dinosaurs), so a donor's window decoded on this skeleton is that action performed by this
animal: motions its own clips lack, which held-out clips often show (BENCHMARKS.md).

The windows one sampling call starts from are drawn together (`diverse_indices`, k-means++
seeding over their latents), not one by one: independent draws follow how many windows each
clip has, so the actions of the longest clips fill most of a batch.

Shapes: Z latent size; ``mean`` (Z,), ``factor`` (Z, Z) with ``factor @ factor.T`` the covariance.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from .skeleton import Skeleton

ALL = "*"  # key of the pooled Gaussian
MAX_DONORS = 8  # donors kept per skeleton; sampling uses the first `MotionConfig.donors`


class LatentGaussians:
    def __init__(self) -> None:
        self.mean: dict[str, np.ndarray] = {}
        self.factor: dict[str, np.ndarray] = {}
        self.rest: dict[str, np.ndarray] = {}  # normalised rest joint positions (J, 3) per key
        # "mixture" sampling: the posterior means (N, Z) themselves and the mean posterior sigma (Z,)
        self.points: dict[str, np.ndarray] = {}
        self.sigma: dict[str, np.ndarray] = {}
        # per joint, the largest angle (degrees) its training windows turn away from rest (J,):
        # samples are kept inside it (`limit_rotations`), so no bone turns further than the data's
        self.max_angle: dict[str, np.ndarray] = {}
        self.donors: dict[str, list[str]] = {}  # see `donors_of`; filled on first use when absent

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
        mus, sig = [], []
        for s in range(0, len(dataset), batch_size):
            b = dataset.batch(np.arange(s, min(len(dataset), s + batch_size)), dev)
            m, lv = model.encode(b.rot6d, b.skeletons)
            mus.append(m.double().cpu().numpy())
            sig.append(torch.exp(0.5 * lv).double().cpu().numpy())
        mu, sigma = np.concatenate(mus), np.concatenate(sig)
        out = cls()
        ids = np.asarray(dataset.skel_ids)
        for sid, sk in enumerate(dataset.skeletons):
            sel = mu[ids == sid]
            if len(sel):
                out.mean[sk.key], out.factor[sk.key] = cls._gaussian(sel)
                out.rest[sk.key] = sk.rest_positions
                out.points[sk.key] = sel.astype(np.float32)
                out.sigma[sk.key] = sigma[ids == sid].mean(0)
                win = np.stack([dataset._rot6d[i][:, : sk.num_joints] for i in np.flatnonzero(ids == sid)])
                out.max_angle[sk.key] = rot6d_angle_deg(win).max(axis=(0, 1))
        out.mean[ALL], out.factor[ALL] = cls._gaussian(mu)
        out.donors = {k: out.donors_of(k, MAX_DONORS) for k in out.points}
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

    def donors_of(self, key: str, count: int = 3, reach: float = 0.45, gap: float = 2.0) -> list[str]:
        """Up to ``count`` trained skeletons whose window latents overlap ``key``'s, nearest first.

        Distance: the symmetric mean nearest-neighbour (Chamfer) distance between the two sets of
        posterior means; a donor is kept when it is at most ``reach`` times the sum of the two
        sets' radii (mean distance to their centre) and at most ``gap`` times the nearest donor's
        distance: animals of one body plan pass, an animal alone in its plan gets none, and in a
        briefly trained prior, whose plans still overlap, only the nearest cluster counts
        (BENCHMARKS.md).
        """
        cached = self.donors.get(key)  # stored with the prior: what it was trained and measured with
        if cached is not None:
            return cached[:count]
        if key not in self.points or count < 1:
            return []
        own = self.points[key].astype(np.float64)
        r_own = _radius(own)
        dist = {}
        for other, pts in self.points.items():
            if other != key:
                pts = pts.astype(np.float64)
                d = _chamfer(own, pts)
                if d <= reach * (r_own + _radius(pts)):
                    dist[other] = d
        out = sorted(dist, key=dist.__getitem__)
        out = [d for d in out if dist[d] <= gap * dist[out[0]]]
        self.donors[key] = out[: max(count, MAX_DONORS)]
        return out[:count]

    def sample(
        self,
        skeleton: Skeleton,
        n: int,
        temperature: float,
        gen: torch.Generator,
        mixture: bool = False,
        donors: int = 0,
        donor_share: float = 0.5,
        diverse: bool = False,
    ) -> torch.Tensor:
        """(n, Z) latents; ``temperature`` scales the spread around the skeleton's mean latent, or
        with ``mixture`` around a random training window's posterior mean (the aggregate posterior
        itself, a mixture of the windows' posteriors: a single Gaussian blends a walk's latents
        with an eating's into poses of neither). With ``donors`` > 0, a ``donor_share`` of the
        windows comes from the skeleton's donors (`donors_of`), spread by their own sigma. With
        ``diverse``, the n windows are drawn together by `diverse_indices` instead of one by one,
        so the n latents are far apart (in draw order: the first ones are the most spread)."""
        k = self.key_for(skeleton)
        if mixture and k in self.points:
            pick = diverse_indices if diverse else _uniform_indices
            pts = torch.as_tensor(self.points[k], dtype=torch.float32)
            base = torch.empty(n, pts.shape[1])
            sigma = torch.as_tensor(self.sigma[k], dtype=torch.float32).expand(n, -1).clone()
            names = self.donors_of(k, donors) if donors > 0 and donor_share > 0 else []
            names = [d for d in names if d in self.points]
            borrow = torch.rand(n, generator=gen) < donor_share if names else torch.zeros(n, dtype=torch.bool)
            own = torch.nonzero(~borrow).flatten()
            base[own] = pts[pick(pts, len(own), gen)]
            if borrow.any():
                other = torch.as_tensor(np.concatenate([self.points[d] for d in names]), dtype=torch.float32)
                owner = np.repeat(
                    np.arange(len(names)), [len(self.points[d]) for d in names]
                )  # donor of each
                other_sigma = torch.as_tensor(np.stack([self.sigma[d] for d in names]), dtype=torch.float32)
                lent = torch.nonzero(borrow).flatten()
                j = pick(other, len(lent), gen)
                base[lent], sigma[lent] = other[j], other_sigma[owner[j.numpy()]]
            eps = torch.randn(n, pts.shape[1], generator=gen)
            return base + temperature * eps * sigma
        m = torch.as_tensor(self.mean[k], dtype=torch.float32)
        f = torch.as_tensor(self.factor[k], dtype=torch.float32)
        eps = torch.randn(n, len(m), generator=gen)
        return m + temperature * eps @ f.T

    def limit_rotations(self, skeleton: Skeleton, q: np.ndarray) -> np.ndarray:
        """Rest-relative rotations q (..., J, 4) with every joint's angle from rest clamped to
        the largest its skeleton's training windows show (unchanged for an unknown skeleton)."""
        k = self.key_for(skeleton)
        if k not in self.max_angle or len(self.max_angle[k]) != q.shape[-2]:
            return q
        return clamp_angle(q, self.max_angle[k])

    # -- persistence ------------------------------------------------------------------------
    def save(self, path: str | Path) -> None:
        arrays = {}
        for i, k in enumerate(self.mean):
            arrays[f"mean_{i}"], arrays[f"factor_{i}"] = self.mean[k], self.factor[k]
            if k in self.rest:
                arrays[f"rest_{i}"] = self.rest[k]
            if k in self.points:
                arrays[f"points_{i}"], arrays[f"sigma_{i}"] = self.points[k], self.sigma[k]
            if k in self.max_angle:
                arrays[f"max_angle_{i}"] = self.max_angle[k]
            if k in self.donors:
                arrays[f"donors_{i}"] = np.array([str(d) for d in self.donors[k]], dtype=str)
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
                if f"points_{i}" in z:
                    out.points[k], out.sigma[k] = z[f"points_{i}"], z[f"sigma_{i}"]
                if f"max_angle_{i}" in z:
                    out.max_angle[k] = z[f"max_angle_{i}"]
                if f"donors_{i}" in z:
                    out.donors[k] = [str(d) for d in z[f"donors_{i}"].tolist()]
        return out


def _uniform_indices(points: torch.Tensor, n: int, gen: torch.Generator) -> torch.Tensor:
    """(n,) indices into points (N, Z), each uniform and independent."""
    return torch.randint(len(points), (n,), generator=gen)


def diverse_indices(points: torch.Tensor, n: int, gen: torch.Generator) -> torch.Tensor:
    """(n,) indices into points (N, Z) drawn as k-means++ seeds: the first uniformly, each next one
    with probability proportional to its squared distance to the nearest already drawn.

    Independent draws follow the windows' frequencies, so a long walk clip's many overlapping
    windows fill most of a batch; these draws cover the skeleton's repertoire first (where many
    windows lie close together, one stands for them all). After every point has been drawn
    (n > N), a new round starts.
    """
    p = points.double()
    out = torch.empty(n, dtype=torch.long)
    d2 = torch.zeros(len(p), dtype=torch.float64)
    for i in range(n):
        total = float(d2.sum())
        if total > 0:
            j = int(torch.multinomial(d2 / total, 1, generator=gen))
        else:  # first draw, or every point drawn already
            j = int(torch.randint(len(p), (1,), generator=gen))
        out[i] = j
        dj = ((p - p[j]) ** 2).sum(1)
        d2 = dj if total <= 0 else torch.minimum(d2, dj)
    return out


def _radius(points: np.ndarray) -> float:
    """Mean distance of points (N, Z) to their centre."""
    return float(np.linalg.norm(points - points.mean(0), axis=1).mean())


def _chamfer(a: np.ndarray, b: np.ndarray) -> float:
    """Symmetric mean nearest-neighbour distance between point sets a (N, Z) and b (M, Z)."""
    d = (a**2).sum(1)[:, None] + (b**2).sum(1)[None] - 2 * a @ b.T
    d = np.sqrt(np.maximum(d, 0.0))
    return 0.5 * float(d.min(1).mean() + d.min(0).mean())


def rot6d_angle_deg(r: np.ndarray) -> np.ndarray:
    """Angle from the identity (degrees) of 6D rotations (..., 6) (first two matrix columns)."""
    a, b = r[..., :3], r[..., 3:]
    a = a / np.linalg.norm(a, axis=-1, keepdims=True).clip(1e-9)
    b = b - (a * b).sum(-1, keepdims=True) * a
    b = b / np.linalg.norm(b, axis=-1, keepdims=True).clip(1e-9)
    c = np.cross(a, b)
    trace = a[..., 0] + b[..., 1] + c[..., 2]
    return np.degrees(np.arccos(np.clip((trace - 1) / 2, -1.0, 1.0)))


def clamp_angle(q: np.ndarray, max_deg: np.ndarray) -> np.ndarray:
    """Unit quaternions q (..., J, 4) wxyz turned back towards the identity where their angle
    exceeds max_deg (J,) degrees; the axis is kept."""
    q = np.where(q[..., :1] < 0, -q, q)
    half = np.arccos(np.clip(q[..., 0], -1.0, 1.0))  # (..., J): half the angle
    limit = np.radians(np.asarray(max_deg, dtype=np.float64)) / 2
    new = np.minimum(half, limit)
    axis = q[..., 1:] / np.maximum(np.sin(half), 1e-12)[..., None]
    out = np.concatenate([np.cos(new)[..., None], axis * np.sin(new)[..., None]], -1)
    return np.where((half > limit)[..., None], out, q)
