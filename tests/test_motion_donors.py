"""Mixture sampling borrows windows from donor skeletons whose latents overlap (issue 24), and
the PCA baseline can be scored at other spreads (MCD at equal diversity)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from zooctl.errors import InputError
from zooctl.motion.baselines import PCABaseline
from zooctl.motion.dataset import MotionSequence
from zooctl.motion.evaluate import pca_curve
from zooctl.motion.latents import LatentGaussians
from zooctl.motion.model import MotionConfig
from zooctl.motion.skeleton import Skeleton


def _chain(name: str, joints: int) -> Skeleton:
    pos = np.zeros((joints, 3))
    pos[:, 1] = np.arange(joints)
    return Skeleton.from_joint_positions(name, np.arange(joints) - 1, pos)


def _latents() -> tuple[LatentGaussians, dict[str, Skeleton]]:
    """Three skeletons: a and b with overlapping latent clouds, c far from both."""
    rng = np.random.default_rng(0)
    sks = {n: _chain(n, j) for n, j in (("a", 3), ("b", 4), ("c", 5))}
    centre = {"a": 0.0, "b": 0.5, "c": 40.0}
    lat = LatentGaussians()
    for n, sk in sks.items():
        pts = centre[n] + rng.normal(size=(60, 4))
        lat.mean[sk.key], lat.factor[sk.key] = LatentGaussians._gaussian(pts)
        lat.rest[sk.key] = sk.rest_positions
        lat.points[sk.key] = pts.astype(np.float32)
        lat.sigma[sk.key] = np.full(4, 0.1)
    return lat, sks


def test_donors_are_the_overlapping_skeletons_only():
    lat, sks = _latents()
    a, b, c = (sks[n].key for n in "abc")
    assert lat.donors_of(a) == [b]
    assert lat.donors_of(b) == [a]
    assert lat.donors_of(c) == []  # an isolated animal borrows nothing
    assert lat.donors_of(a, 0) == []


def test_donor_share_decides_where_the_windows_come_from():
    lat, sks = _latents()
    a, b = sks["a"].key, sks["b"].key
    gen = torch.Generator().manual_seed(0)

    def nearest_owner(z: torch.Tensor) -> np.ndarray:
        own = np.abs(z.numpy()[:, None] - lat.points[a][None]).sum(-1).min(1)
        other = np.abs(z.numpy()[:, None] - lat.points[b][None]).sum(-1).min(1)
        return own < other

    z_own = lat.sample(sks["a"], 200, 0.0, gen, mixture=True, donors=0)
    assert nearest_owner(z_own).all()
    z_all = lat.sample(sks["a"], 200, 0.0, gen, mixture=True, donors=3, donor_share=1.0)
    assert not nearest_owner(z_all).any()
    z_half = lat.sample(sks["a"], 400, 0.0, gen, mixture=True, donors=3, donor_share=0.5)
    assert 0.4 < nearest_owner(z_half).mean() < 0.6
    # The isolated skeleton draws its own windows whatever the share.
    z_c = lat.sample(sks["c"], 50, 0.0, gen, mixture=True, donors=3, donor_share=1.0)
    assert float(z_c.mean()) > 30


def test_donors_survive_save_and_load(tmp_path):
    lat, sks = _latents()
    lat.donors = {k: lat.donors_of(k, 8) for k in list(lat.points)}
    lat.save(tmp_path / "latents.npz")
    again = LatentGaussians.load(tmp_path / "latents.npz")
    assert again.donors == lat.donors
    assert again.donors_of(sks["a"].key, 1) == [sks["b"].key]


def test_bad_donor_settings_are_clear_errors():
    with pytest.raises(InputError, match="donor_share"):
        MotionConfig(donor_share=1.5)
    with pytest.raises(InputError, match="donors"):
        MotionConfig(donors=-1)
    assert MotionConfig.from_json({"width": 64, "layers": 2}).donors == MotionConfig.donors


def _swinging(sk: Skeleton, name: str, amp: float) -> MotionSequence:
    t = np.arange(40) / 30.0
    q = np.zeros((len(t), sk.num_joints, 4))
    q[..., 0] = 1.0
    a = amp * np.sin(2 * np.pi * t)
    q[:, 1, 0], q[:, 1, 3] = np.cos(a / 2), np.sin(a / 2)
    return MotionSequence(name, sk, q, 30.0)


def test_pca_spread_scales_the_baselines_diversity():
    sk = _chain("c", 4)
    train = [_swinging(sk, f"c/{i}", a) for i, a in enumerate((0.2, 0.5, 0.9))]
    test = [_swinging(sk, "c/held", 0.7)]
    curve = pca_curve(train, test, 8, 30.0, [0.0, 0.5, 1.0], samples=8, seeds=2)
    assert [c["spread"] for c in curve] == [0.0, 0.5, 1.0]
    assert curve[0]["diversity"] < 1e-6 < curve[1]["diversity"] < curve[2]["diversity"]
    pca = PCABaseline()
    pca.add(sk, np.stack([s.rotations[:8] for s in train]))
    np.testing.assert_allclose(pca.sample(sk, 3, seed=1), pca.sample(sk, 3, seed=1, spread=1.0))


def test_only_the_nearest_cluster_of_donors_counts():
    """A near twin (as the starter bank's variants sharing clips) makes a merely overlapping
    skeleton too far to lend: in a briefly trained prior all plans still overlap."""
    rng = np.random.default_rng(1)
    base = rng.normal(size=(60, 4))
    lat = LatentGaussians()
    for name, pts in (
        ("a", base),
        ("twin", base + 0.01 * rng.normal(size=base.shape)),
        ("near", 0.5 + rng.normal(size=(60, 4))),
    ):
        lat.points[name], lat.sigma[name] = pts.astype(np.float32), np.full(4, 0.1)
    assert lat.donors_of("a") == ["twin"]
    lat.donors = {}
    assert lat.donors_of("a", gap=100.0) == ["twin", "near"]
