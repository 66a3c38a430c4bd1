"""One sampling call's windows are drawn together and spread over the skeleton's latents
(k-means++ seeding), not one by one (issue 24: five samples should be five actions)."""

from __future__ import annotations

import numpy as np
import torch

from zooctl.motion.latents import LatentGaussians, diverse_indices
from zooctl.motion.skeleton import Skeleton


def _clusters(sizes: tuple[int, ...]) -> tuple[torch.Tensor, np.ndarray]:
    """Points in len(sizes) tight, far-apart clusters of the given sizes, and each point's cluster."""
    rng = np.random.default_rng(0)
    centres = 50.0 * np.eye(len(sizes), 6)
    label = np.repeat(np.arange(len(sizes)), sizes)
    pts = centres[label] + 0.1 * rng.normal(size=(len(label), 6))
    return torch.as_tensor(pts, dtype=torch.float32), label


def test_diverse_draws_cover_every_cluster_however_rare():
    # One "long clip" of 400 windows and four short ones of 5: independent draws of 5 windows
    # mostly repeat the long clip; diverse draws take one window of each.
    pts, label = _clusters((400, 5, 5, 5, 5))
    covered_diverse, covered_uniform = [], []
    for seed in range(20):
        gen = torch.Generator().manual_seed(seed)
        covered_diverse.append(len(set(label[diverse_indices(pts, 5, gen).numpy()])))
        covered_uniform.append(len(set(label[torch.randint(len(pts), (5,), generator=gen).numpy()])))
    assert min(covered_diverse) == 5
    assert max(covered_uniform) < 5


def test_diverse_draws_are_seeded_and_start_new_rounds():
    pts, _ = _clusters((3, 3))
    a = diverse_indices(pts, 15, torch.Generator().manual_seed(3))
    b = diverse_indices(pts, 15, torch.Generator().manual_seed(3))
    assert torch.equal(a, b)
    assert a.shape == (15,) and int(a.min()) >= 0 and int(a.max()) < 6
    # n > N: the first round draws every point once before any point is drawn again
    assert len(set(a[:6].tolist())) == 6


def _chain(name: str, joints: int) -> Skeleton:
    pos = np.zeros((joints, 3))
    pos[:, 1] = np.arange(joints)
    return Skeleton.from_joint_positions(name, np.arange(joints) - 1, pos)


def test_mixture_sampling_spreads_a_calls_windows():
    pts, label = _clusters((200, 4, 4, 4))
    sk = _chain("a", 3)
    lat = LatentGaussians()
    lat.mean[sk.key], lat.factor[sk.key] = LatentGaussians._gaussian(pts.double().numpy())
    lat.rest[sk.key] = sk.rest_positions
    lat.points[sk.key] = pts.numpy()
    lat.sigma[sk.key] = np.full(6, 0.01)
    centres = np.stack([pts.numpy()[label == c].mean(0) for c in range(4)])

    def clusters_hit(z: torch.Tensor) -> int:
        d = ((z.numpy()[:, None] - centres[None]) ** 2).sum(-1)
        return len(set(d.argmin(1).tolist()))

    gen = torch.Generator().manual_seed(0)
    hits = [clusters_hit(lat.sample(sk, 4, 1.0, gen, mixture=True, diverse=True)) for _ in range(10)]
    assert min(hits) == 4
    hits = [clusters_hit(lat.sample(sk, 4, 1.0, gen, mixture=True, diverse=False)) for _ in range(10)]
    assert max(hits) < 4
