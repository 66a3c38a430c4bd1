"""Priors: sign-invariant smoothness, a symmetry plane found (not assumed), bone-length pairs."""

from pathlib import Path

import numpy as np
import pytest
import torch

from zooctl.errors import InputError
from zooctl.rig.priors import (
    bone_length_prior,
    find_symmetry_plane,
    reflect,
    smoothness_loss,
    symmetric_joint_pairs,
    symmetry_loss,
)
from zooctl.rig.rotations import axis_angle_to_quat, quat_to_matrix

ASSETS = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "assets" / "quaternius"


def test_smoothness_is_sign_invariant_and_grows_with_motion():
    gen = torch.Generator().manual_seed(0)
    q = axis_angle_to_quat(torch.randn(1, 5, 3, generator=gen)).expand(6, 5, 4).clone()
    q[1::2] *= -1  # same rotations, alternating sign
    assert smoothness_loss(q) < 1e-6  # float32 rounding leaves about 1e-7
    moving = axis_angle_to_quat(torch.linspace(0, 1, 6)[:, None, None] * torch.tensor([0.0, 0.0, 1.0]))
    fast = axis_angle_to_quat(torch.linspace(0, 3, 6)[:, None, None] * torch.tensor([0.0, 0.0, 1.0]))
    assert 0 < smoothness_loss(moving) < smoothness_loss(fast)


def _mirrored_cloud(seed=0):
    rng = np.random.default_rng(seed)
    half = rng.normal(size=(600, 3)) * [0.6, 1.0, 2.0]
    half[:, 0] = np.abs(half[:, 0]) + 0.05
    pts = np.concatenate((half, half * [-1, 1, 1]))  # mirror plane x = 0
    R = quat_to_matrix(torch.as_tensor(rng.normal(size=4))).numpy()
    t = np.array([0.3, -2.0, 1.5])
    return pts @ R.T + t, R[:, 0], float(R[:, 0] @ t)


def test_symmetry_plane_is_found_under_a_random_rigid_transform():
    pts, n_true, d_true = _mirrored_cloud()
    n, d, rms = find_symmetry_plane(pts)
    sign = np.sign(n @ n_true)
    assert np.degrees(np.arccos(min(1.0, abs(n @ n_true)))) < 0.5
    assert abs(sign * d - d_true) < 1e-2
    assert rms < 1e-3
    # Chamfer symmetry loss: ~0 for the symmetric cloud, larger once one side is bent away.
    P = torch.as_tensor(pts, dtype=torch.float64)
    nt = torch.as_tensor(n)
    assert symmetry_loss(P, nt, d) < 1e-6
    bent = P.clone().requires_grad_(True)
    side = (P @ nt - d) > 0
    loss = symmetry_loss(bent + side[:, None] * 0.2 * nt, nt, d)
    loss.backward()
    assert loss > 1e-3 and bent.grad.abs().sum() > 0
    assert torch.allclose(reflect(reflect(P, nt, d), nt, d), P, atol=1e-10)


@pytest.mark.skipif(not ASSETS.is_dir(), reason=f"shared Quaternius assets not found at {ASSETS}")
def test_asset_plane_and_mirrored_leg_bones():
    from zooctl.io.gltf_import import load_gltf

    asset = load_gltf(ASSETS / "animals_pack" / "Horse.glb", "Horse")
    n, d, rms = find_symmetry_plane(asset.vertices)
    assert abs(n[0]) > 0.999 and rms < 0.01  # the horse is modelled facing along Z, mirrored in X
    heads = asset.bind_joint_positions()
    pairs = symmetric_joint_pairs(heads, n, d, tol=0.02 * asset.size())
    names = {(asset.joint_names[a], asset.joint_names[b]) for a, b in pairs}
    assert len(pairs) >= 4 and any(("L" in a and "R" in b) or ("R" in a and "L" in b) for a, b in names)
    log_b = torch.zeros(asset.num_joints)
    assert bone_length_prior(log_b, torch.as_tensor(pairs)) == 0
    log_b[pairs[0, 0]] = 0.5
    assert bone_length_prior(log_b, torch.as_tensor(pairs)) > bone_length_prior(log_b)


def test_bad_input_is_one_clear_error():
    with pytest.raises(InputError):
        find_symmetry_plane(np.zeros((2, 3)))


def test_smoothness_equals_the_hamilton_product_form():
    """Eq. 6 through w(q_t * conj(q_t+1)), the product taken in full, as the dot product it is."""
    from zooctl.rig.rotations import quat_conjugate, quat_mul

    gen = torch.Generator().manual_seed(2)
    q = torch.nn.functional.normalize(torch.randn(2, 7, 5, 4, generator=gen, dtype=torch.float64), dim=-1)
    q.requires_grad_(True)
    rel = quat_mul(q[..., :-1, :, :], quat_conjugate(q[..., 1:, :, :]))
    want = (1.0 - rel[..., 0] ** 2).mean()
    got = smoothness_loss(q)
    torch.testing.assert_close(got, want, rtol=1e-12, atol=1e-14)
    torch.testing.assert_close(torch.autograd.grad(got, q)[0], torch.autograd.grad(want, q)[0])
