"""Motion data, skeleton FK, metrics and baselines (issue 8): no training here."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from conftest import ASSETS_DIR, needs_shared_assets

from zooctl.errors import InputError
from zooctl.geometry import matrix_to_quat, quat_to_matrix
from zooctl.motion import metrics as M
from zooctl.motion.baselines import PCABaseline, RetrievalBaseline
from zooctl.motion.dataset import (
    MotionDataset,
    MotionSequence,
    holdout_split,
    resample,
    sequence_from_clip,
    sequence_from_fit,
    sequences_from_asset,
    windows,
)
from zooctl.motion.skeleton import Skeleton, SkeletonBatch
from zooctl.procedural import build_animal


@pytest.fixture(scope="module")
def quadruped():
    return build_animal("quadruped")


@pytest.fixture(scope="module")
def fish():
    return build_animal("fish")


def _axis_rotation(angles: np.ndarray, axis=(0.0, 0.0, 1.0)) -> np.ndarray:
    a = np.asarray(axis) / np.linalg.norm(axis)
    return np.concatenate([np.cos(angles / 2)[:, None], np.sin(angles / 2)[:, None] * a], -1)


def test_clip_rotations_are_relative_to_rest_and_round_trip(quadruped):
    seq = sequence_from_clip(quadruped, "walk")
    clip = quadruped.clips["walk"]
    assert seq.rotations.shape == clip.rotations.shape
    back = seq.local_rotations()
    assert np.allclose(np.abs((back * clip.rotations).sum(-1)), 1.0, atol=1e-9)  # same rotation (q or -q)
    # A clip that holds the rest pose is the identity everywhere.
    rest = Skeleton.from_asset(quadruped)
    still = MotionSequence("still", rest, np.tile([1.0, 0, 0, 0], (4, quadruped.num_joints, 1)), 30.0)
    assert np.allclose(
        still.local_rotations(), np.broadcast_to(rest.rest_rotations, (4, quadruped.num_joints, 4))
    )


def test_unknown_clip_is_a_clear_error(quadruped):
    with pytest.raises(InputError, match="no clip"):
        sequence_from_clip(quadruped, "moonwalk")


def test_resample_interpolates_on_the_sphere():
    sk = Skeleton.from_joint_positions("bar", np.array([-1, 0]), np.array([[0.0, 0, 0], [0, 1, 0]]))
    angles = np.linspace(0, 1.0, 31)  # constant angular speed, 30 fps, one second
    q = np.stack([_axis_rotation(angles), _axis_rotation(angles)], 1)
    seq = MotionSequence("spin", sk, q, 30.0)
    half = resample(seq, 15.0)
    assert half.num_frames == 16 and half.fps == 15.0
    assert np.allclose(half.rotations[:, 0], _axis_rotation(angles[::2]), atol=1e-9)
    double = resample(seq, 60.0)
    assert double.num_frames == 61
    assert np.allclose(double.rotations[1, 0], _axis_rotation(np.array([angles[1] / 2]))[0], atol=1e-9)


def test_windows_cover_the_sequence_and_end_flush():
    sk = Skeleton.from_joint_positions("bar", np.array([-1, 0]), np.array([[0.0, 0, 0], [0, 1, 0]]))
    q = np.stack([_axis_rotation(np.arange(23) * 0.01)] * 2, 1)
    w = windows(MotionSequence("s", sk, q, 30.0), 10, 5)
    assert w.shape == (4, 10, 2, 4)  # starts 0, 5, 10, 13
    assert np.allclose(w[-1], q[13:])
    assert len(windows(MotionSequence("s", sk, q[:9], 30.0), 10, 5)) == 0


def test_holdout_split_is_stable_and_never_takes_everything():
    names = {"a": [f"c{i}" for i in range(10)], "b": ["x", "y"], "c": ["only"]}
    s1 = holdout_split(names, 0.2)
    assert s1 == holdout_split(dict(reversed(list(names.items()))), 0.2)
    assert len(s1["a"]) == 2 and len(s1["b"]) == 1 and "c" not in s1
    assert holdout_split(names, 0.0) == {}
    assert len(holdout_split(names, 0.9)["b"]) == 1


def test_fit_sequences_build_their_skeleton_from_joint_positions():
    parents = np.array([-1, 0, 1, 0])
    pos = np.array([[0.0, 1, 0], [0, 1, -1], [0, 0, -1], [0, 1, 1]])
    rots = np.tile([1.0, 0, 0, 0], (5, 4, 1))
    seq = sequence_from_fit("fit1", parents, pos, rots, 25.0)
    assert seq.source == "fit" and seq.fps == 25.0
    sk = seq.skeleton
    sb = SkeletonBatch([sk])
    p = sb.joint_positions(torch.eye(3).expand(1, 1, 4, 3, 3))[0, 0].numpy()
    assert np.allclose(p * sk.scale + sk.center, pos, atol=1e-5)
    with pytest.raises(InputError, match="local rotations"):
        sequence_from_fit("fit1", parents, pos, rots[:, :3], 25.0)
    with pytest.raises(InputError, match="rest joint positions"):
        sequence_from_fit("fit1", parents, pos[:3], rots, 25.0)
    with pytest.raises(InputError, match="fps"):
        sequence_from_fit("fit1", parents, pos, rots, 0.0)


def test_padded_fk_matches_numpy_fk_for_mixed_skeletons(quadruped, fish):
    """Joint positions through the padded batch equal the asset's own (numpy) FK of a clip frame."""
    batch = SkeletonBatch([Skeleton.from_asset(fish), Skeleton.from_asset(quadruped)])
    assert (
        batch.num_joints == quadruped.num_joints
        and batch.mask.sum() == fish.num_joints + quadruped.num_joints
    )
    deltas = []
    for a, clip in ((fish, "swim"), (quadruped, "walk")):
        seq = sequence_from_clip(a, clip)
        d = np.tile(np.eye(3), (1, 1, batch.num_joints, 1, 1))
        d[0, 0, : a.num_joints] = quat_to_matrix(seq.rotations[3])
        deltas.append(d[0])
    pos = batch.joint_positions(torch.as_tensor(np.stack(deltas), dtype=torch.float32)).numpy()
    for b, (a, clip) in enumerate(((fish, "swim"), (quadruped, "walk"))):
        c = a.clips[clip]
        local = c.local_matrices(3).copy()
        local[:, :3, 3] = a.rest_local[:, :3, 3]  # root motion is not modelled
        ref = a.joint_transforms(local)[:, :3, 3]
        sk = batch.skeletons[b]
        assert np.allclose(pos[b, 0, : a.num_joints] * sk.scale + sk.center, ref, atol=1e-4 * sk.scale)


@needs_shared_assets
def test_fk_handles_armature_scale_of_real_assets():
    """Quaternius armatures carry a 100x scale node: normalised rest positions must still span 1."""
    from zooctl.io.gltf_import import load_gltf

    fox = load_gltf(ASSETS_DIR / "animals_pack" / "Fox.glb", "Fox")
    sk = Skeleton.from_asset(fox)
    ident = torch.eye(3).expand(1, 1, fox.num_joints, 3, 3)
    p = SkeletonBatch([sk]).joint_positions(ident)[0, 0].numpy()
    assert np.allclose(p, sk.rest_positions, atol=1e-5)
    assert np.isclose(np.linalg.norm(p.max(0) - p.min(0)), 1.0, atol=1e-5)
    assert len(sk.feet()) >= 4  # four hooves / paws on the ground


def test_dataset_pads_with_identity_and_serves_every_window_once(quadruped, fish):
    seqs = sequences_from_asset(quadruped) + sequences_from_asset(fish)
    ds = MotionDataset(seqs, length=8, speeds=(0.8,))
    seen = []
    rng = np.random.default_rng(0)
    for b in ds.batches(16, rng):
        J = b.skeletons.num_joints
        assert b.rot6d.shape[1:] == (8, J, 6)
        pad = ~b.skeletons.mask
        if pad.any():
            ident = torch.tensor([1.0, 0, 0, 0, 1, 0])
            assert torch.allclose(
                b.rot6d.permute(0, 2, 1, 3)[pad], ident.expand_as(b.rot6d.permute(0, 2, 1, 3)[pad])
            )
        seen.append(len(b.rot6d))
    assert sum(seen) == len(ds)
    with pytest.raises(InputError, match="no motion windows"):
        MotionDataset(seqs, length=500)


def test_metrics_on_known_motions():
    sk = Skeleton.from_joint_positions(
        "leg", np.array([-1, 0, 1]), np.array([[0.0, 1, 0], [0, 0.5, 0], [0, 0, 0]])
    )
    T = 10
    still = np.tile([1.0, 0, 0, 0], (3, T, 3, 1))
    p_still = M.joint_positions(still, sk)
    assert M.motion_chamfer(p_still, p_still) == pytest.approx(0.0, abs=1e-9)
    assert M.diversity(p_still) == pytest.approx(0.0, abs=1e-9)
    assert M.smoothness(p_still) == pytest.approx(0.0, abs=1e-9)
    assert M.foot_sliding(p_still, np.array([1, 2])) == pytest.approx(0.0, abs=1e-9)
    # Swinging the hip at constant speed: non-zero diversity against the still set, zero acceleration
    # of the angle (small but non-zero for positions on a circle), and the swinging foot slides.
    swing = still.copy()
    swing[:, :, 0] = _axis_rotation(np.linspace(0, 0.2, T))[None]
    p_swing = M.joint_positions(swing, sk)
    d = M.motion_chamfer(p_swing, p_still)
    assert d > 0 and d == pytest.approx(M.motion_chamfer(p_still, p_swing))
    assert M.diversity(np.concatenate([p_still[:1], p_swing[:1]])) > 0
    assert M.smoothness(p_swing) < 0.05 * M.diversity(np.concatenate([p_still[:1], p_swing[:1]]))
    assert M.foot_sliding(p_swing, np.array([1, 2]), contact=100.0) > 0
    assert M.foot_sliding(p_swing, np.array([2])) is None  # fewer than two feet: not a legged animal


def test_baselines_sample_valid_rotations(quadruped):
    sk = Skeleton.from_asset(quadruped)
    w = np.concatenate([windows(resample(s, 30.0), 10, 5) for s in sequences_from_asset(quadruped)])
    pca, ret = PCABaseline(components=8), RetrievalBaseline()
    pca.add(sk, w)
    ret.add(sk, w)
    s = pca.sample(sk, 6, seed=1)
    assert s.shape == (6, 10, quadruped.num_joints, 4)
    assert np.allclose(np.linalg.norm(s, axis=-1), 1.0, atol=1e-6)
    assert not np.allclose(s[0], s[1])
    r = ret.sample(sk, 3, seed=0)
    assert all(any(np.allclose(x, y) for y in w) for x in r)
    other = Skeleton.from_joint_positions("other", np.array([-1]), np.zeros((1, 3)))
    with pytest.raises(InputError, match="no training data"):
        pca.sample(other, 2)


def test_rot6d_matrix_round_trip_is_exact():
    from zooctl.motion.baselines import rot6d_to_matrix_np
    from zooctl.motion.dataset import matrix_to_rot6d

    q = np.random.default_rng(0).normal(size=(20, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    m = quat_to_matrix(q)
    back = matrix_to_quat(rot6d_to_matrix_np(matrix_to_rot6d(m)))
    assert np.allclose(np.abs((back * q).sum(-1)), 1.0, atol=1e-9)
