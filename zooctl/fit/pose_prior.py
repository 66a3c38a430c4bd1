"""Pose priors on the fitted joint rotations (``FitConfig.pose_prior``: none, rest, clips, motion).

``rest``: rotations near the rest pose (`zooctl.fit.losses.pose_prior`). ``clips``: a Gaussian per
joint over the rotation vector of rest^-1 q, learned from the template's own clips (every frame of
every clip): how this skeleton moves. The loss is the mean Mahalanobis distance per degree of
freedom; each joint's standard deviations are floored at ``min_std_deg`` (joints a clip never
moves still may move a little, and a template's clips are not the video animal's motion).
Without clips the prior falls back to ``rest`` statistics: mean 0, the floor as the deviation.
``motion``: a trained motion prior scores windows of the fitted motion (`motion_sequence_prior`;
for ``ponymation`` priors its VAE's negative ELBO, `zooctl.motion.fit_prior`).

Joint limits (``weights.joint_limits``, with any kind): each joint's range per axis of the same
rotation vector over the template's clips, widened by ``pose_prior.limit_margin_deg`` on both
sides (`clip_joint_limits`); the fit pays only for rotations outside it. Unlike the clips
Gaussian it does not pull towards the clips' mean pose, so another animal's clips hold the fit
only where it would bend a joint further than that skeleton ever does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ..asset import RiggedAsset
from ..rig.rotations import quat_conjugate, quat_mul, quat_normalize, quat_to_axis_angle

Tensor = torch.Tensor


@dataclass
class ClipPoseStats:
    """Per joint: mean (J, 3) and precision (J, 3, 3) of rest^-1 q's rotation vector; frames: how
    many clip frames they were estimated from (0: the fallback). Their loss is
    `zooctl.fit.losses.clip_pose_loss`."""

    mean: Tensor
    precision: Tensor
    frames: int


def clip_pose_stats(asset: RiggedAsset, min_std_deg: float = 10.0, device: str = "cpu") -> ClipPoseStats:
    """The template's clip statistics (module docstring)."""
    J = len(asset.parents)
    vectors = clip_rotation_vectors(asset)
    floor = math.radians(min_std_deg) ** 2 * torch.eye(3, dtype=torch.float64)
    if vectors is None:
        mean = torch.zeros(J, 3, dtype=torch.float64)
        cov = floor.expand(J, 3, 3)
        n = 0
    else:
        aa = torch.as_tensor(vectors)  # (N, J, 3)
        mean = aa.mean(0)
        d = aa - mean
        cov = torch.einsum("nja,njb->jab", d, d) / max(len(aa) - 1, 1)
        # Floor the deviations: eigenvalues below the floor's variance are raised to it.
        w, V = torch.linalg.eigh(cov)
        w = w.clamp_min(float(floor[0, 0]))
        cov = V @ torch.diag_embed(w) @ V.transpose(-1, -2)
        n = len(aa)
    prec = torch.linalg.inv(cov)
    return ClipPoseStats(mean.float().to(device), prec.float().to(device), n)


@dataclass
class JointLimits:
    """Per joint and axis: the lowest and highest (J, 3) rotation-vector component of rest^-1 q
    (radians) the fit may use without cost; frames: how many clip frames they come from. Their
    loss is `zooctl.fit.losses.joint_limit_loss`."""

    low: Tensor
    high: Tensor
    frames: int


def clip_rotation_vectors(asset: RiggedAsset) -> np.ndarray | None:
    """(N, J, 3) rest^-1 q as rotation vectors over every frame of the template's clips (None
    without clips of this skeleton)."""
    _, rest_q, _ = asset.rest_trs()
    J = len(asset.parents)
    rots = [np.asarray(c.rotations) for c in asset.clips.values() if c.rotations.shape[1:] == (J, 4)]
    if not rots:
        return None
    rest = torch.as_tensor(np.asarray(rest_q), dtype=torch.float64)
    q = torch.as_tensor(np.concatenate(rots), dtype=torch.float64)
    return quat_to_axis_angle(quat_normalize(quat_mul(quat_conjugate(rest)[None], q))).numpy()


def clip_joint_limits(
    asset: RiggedAsset, margin_deg: float = 30.0, device: str = "cpu"
) -> JointLimits | None:
    """The template's joint limits (module docstring); None without clips (nothing to learn a
    range from, so no limits rather than invented ones)."""
    aa = clip_rotation_vectors(asset)
    if aa is None:
        return None
    m = math.radians(margin_deg)
    low = torch.as_tensor(aa.min(0) - m, dtype=torch.float32, device=device)
    high = torch.as_tensor(aa.max(0) + m, dtype=torch.float32, device=device)
    return JointLimits(low, high, len(aa))


def motion_sequence_prior(folder: str | None, asset: RiggedAsset, video_fps: float, device: str = "cpu"):
    """The ``motion`` pose prior: the prior stored in ``folder`` (resolved by the fit job from a
    name) as a prior on ``asset``'s fitted rotations; its ``loss(rotations, frames)`` is the term."""
    from ..errors import UsageError
    from ..store.motion_store import load_prior_dir

    if not folder:
        raise UsageError(
            "the motion pose prior needs a trained motion prior",
            hint='train one with `zooctl motion train`, then {"pose_prior": {"kind": "motion", "motion": "NAME"}}',
        )
    prior = load_prior_dir(Path(folder), device)
    if not callable(getattr(prior, "sequence_prior", None)):
        raise UsageError(
            f"the motion prior in {folder} ({type(prior).__name__}) cannot score a fitted motion",
            hint="use a ponymation prior (`zooctl motion train --kind ponymation`), or another pose prior",
        )
    return prior.sequence_prior(asset, video_fps)
