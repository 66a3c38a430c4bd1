"""Left-right mirrored motions (`zooctl.motion.mirror`): pairing by name, the mirrored pose is the
reflected pose, mirroring twice is the identity, and the prior's dataset gains the mirrors."""

from __future__ import annotations

import numpy as np
import pytest

from zooctl.geometry import compose_trs, global_transforms, quat_to_matrix
from zooctl.motion.dataset import MotionSequence, sequences_from_asset
from zooctl.motion.mirror import mirror_pairs, mirror_plane_normal, mirror_sequence, reflect_quat
from zooctl.motion.model import MotionConfig
from zooctl.motion.prior import PonymationPrior
from zooctl.motion.skeleton import Skeleton
from zooctl.procedural import build_animal


@pytest.fixture(scope="module")
def quadruped():
    return build_animal("quadruped")


def _positions(seq) -> np.ndarray:
    """(T, J, 3) model-space joint positions of a sequence."""
    sk, local = seq.skeleton, seq.local_rotations()
    return np.stack(
        [
            global_transforms(compose_trs(sk.rest_translations, q, sk.rest_scales), sk.parents)[:, :3, 3]
            for q in local
        ]
    )


def test_pairs_by_name():
    names = [
        "Root",
        "Leg.L",
        "Leg.R",
        "LeftArm",
        "RightArm",
        "l_wing",
        "r_wing",
        "tail_l2",
        "Foot2.R",
        "Body",
    ]
    pairs = mirror_pairs(names)
    assert [names[k] for k in pairs] == [
        "Root", "Leg.R", "Leg.L", "RightArm", "LeftArm", "r_wing", "l_wing", "tail_l2", "Foot2.R", "Body"
    ]  # fmt: skip
    # A letter inside a word is not a side: "Tail" and "Head" keep themselves.
    assert list(mirror_pairs(["Tail", "Head", "Lr"])) == [0, 1, 2]


def test_reflected_rotation_is_mirror_conjugate():
    rng = np.random.default_rng(0)
    q = rng.normal(size=(5, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    n = np.array([1.0, 2.0, -0.5])
    n /= np.linalg.norm(n)
    M = np.eye(3) - 2 * np.outer(n, n)
    np.testing.assert_allclose(quat_to_matrix(reflect_quat(q, n)), M @ quat_to_matrix(q) @ M, atol=1e-12)


def test_mirrored_pose_is_the_reflected_pose(quadruped):
    seq = next(s for s in sequences_from_asset(quadruped) if s.name.endswith("/walk"))
    sk = seq.skeleton
    pairs = mirror_pairs(sk.joint_names)
    assert (pairs != np.arange(sk.num_joints)).sum() == 12  # 4 legs x 3 joints
    n = mirror_plane_normal(sk, pairs)
    mirrored = mirror_sequence(seq)
    assert mirrored is not None and mirrored.rotations.shape == seq.rotations.shape
    P, Pm = _positions(seq), _positions(mirrored)
    still = np.tile([1.0, 0, 0, 0], (1, sk.num_joints, 1))
    rest = _positions(MotionSequence(seq.name, sk, still, seq.fps))[0]
    c = rest.mean(0)
    reflected = P[:, pairs] - 2 * ((P[:, pairs] - c) @ n)[..., None] * n
    size = float(np.ptp(rest, axis=0).max())
    assert np.abs(reflected - Pm).max() < 1e-6 * size
    # The walk really moves, so the check above is not between two rest poses.
    assert np.abs(P - P[:1]).max() > 0.05 * size
    # The legs swap sides: the mirrored left front foot does not retrace the original one.
    lf = sk.joint_names.index("front_foot_l")
    assert np.abs(Pm[:, lf] - P[:, lf]).max() > 0.05 * size
    # Twice mirrored is the original motion.
    twice = mirror_sequence(mirrored)
    np.testing.assert_allclose(quat_to_matrix(twice.rotations), quat_to_matrix(seq.rotations), atol=1e-9)


def test_no_mirror_without_side_names(quadruped):
    seq = sequences_from_asset(quadruped)[0]
    sk = seq.skeleton
    plain = Skeleton(
        "unnamed", [f"joint{j}" for j in range(sk.num_joints)], sk.parents,
        sk.rest_translations, sk.rest_rotations, sk.rest_scales,
    )  # fmt: skip
    assert mirror_sequence(MotionSequence(seq.name, plain, seq.rotations, seq.fps)) is None


def test_prior_dataset_adds_mirrors(quadruped):
    seqs = sequences_from_asset(quadruped)
    plain = PonymationPrior(MotionConfig(width=16, layers=1, heads=2, latent=8)).dataset(seqs)
    both = PonymationPrior(MotionConfig(width=16, layers=1, heads=2, latent=8, mirror=True)).dataset(seqs)
    assert len(both) == 2 * len(plain)
    assert len(both.skeletons) == 1  # the mirrors are motions of the same skeleton
    assert sum(n.endswith("(mirrored)") for n in both.sequence_names) == len(seqs)
