"""Pose priors on the fitted joint rotations (``FitConfig.pose_prior``: none, rest, clips, motion).

``rest``: rotations near the rest pose (`zooctl.fit.losses.pose_prior`). ``clips``: a Gaussian per
joint over the rotation vector of rest^-1 q, learned from the template's own clips (every frame of
every clip): how this skeleton moves. The loss is the mean Mahalanobis distance per degree of
freedom; each joint's standard deviations are floored at ``min_std_deg`` (joints a clip never
moves still may move a little, and a template's clips are not the video animal's motion).
Without clips the prior falls back to ``rest`` statistics: mean 0, the floor as the deviation.
``motion``: a trained motion prior scores windows of the fitted motion (`motion_sequence_prior`;
for ``ponymation`` priors its VAE's negative ELBO, `zooctl.motion.fit_prior`).
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
    _, rest_q, _ = asset.rest_trs()
    rest = torch.as_tensor(np.asarray(rest_q), dtype=torch.float64)
    J = len(asset.parents)
    rots = [np.asarray(c.rotations) for c in asset.clips.values() if c.rotations.shape[1:] == (J, 4)]
    floor = math.radians(min_std_deg) ** 2 * torch.eye(3, dtype=torch.float64)
    if not rots:
        mean = torch.zeros(J, 3, dtype=torch.float64)
        cov = floor.expand(J, 3, 3)
        n = 0
    else:
        q = torch.as_tensor(np.concatenate(rots), dtype=torch.float64)  # (N, J, 4)
        aa = quat_to_axis_angle(quat_normalize(quat_mul(quat_conjugate(rest)[None], q)))  # (N, J, 3)
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
