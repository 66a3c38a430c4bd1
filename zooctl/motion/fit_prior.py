"""A trained motion VAE as a prior on a fit's joint rotations (Ponymation's motion space
regularising reconstruction; `zooctl.fit` pose prior ``motion``).

The fitted rotations of a window of video frames, taken at the prior's frame rate (the nearest
video frame to each of its ``length`` frames) and relative to the template's rest pose as in
training (`zooctl.motion.dataset`), are encoded by the VAE and decoded from the posterior mean.
The loss is the negative ELBO with the weights the VAE was trained with: rotation and
joint-position reconstruction errors plus ``kl_weight`` times the KL to N(0, I)
(`zooctl.motion.losses`). Training's velocity terms are left out: they are relative to each
window's own motion, which a still window does not have; its free bits are a training device.
Motion the prior has learned for skeletons like the template's reconstructs well and costs
little; a pose or gait it never saw (a leg bent backwards, a limb jittering) costs more, and
larger motion costs some more KL. The VAE's weights stay fixed: the gradient reaches only the
fitted rotations.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import torch

from ..rig.rotations import (
    matrix_to_rot6d,
    quat_conjugate,
    quat_mul,
    quat_normalize,
    quat_to_matrix,
    rot6d_to_matrix,
)
from .losses import joint_loss, kl_loss, rotation_loss
from .skeleton import Skeleton, SkeletonBatch

if TYPE_CHECKING:
    from ..asset import RiggedAsset
    from .model import MotionConfig, MotionVAE, TrajectoryVAE

Tensor = torch.Tensor


class SequencePrior:
    """``loss(rotations, frames)`` for one template skeleton and one video frame rate.

    model: a motion VAE with ``encode(rot6d (B, L, J, 6), sk) -> mu, logvar`` and
    ``decode(z, sk) -> (B, L, J, 6)``; cfg: its `zooctl.motion.model.MotionConfig` (``length`` L,
    ``fps``); asset: the template; video_fps: frames per second of the fitted video.
    """

    def __init__(
        self,
        model: MotionVAE | TrajectoryVAE,
        cfg: MotionConfig,
        asset: RiggedAsset,
        video_fps: float,
        device: torch.device | str = "cpu",
    ):
        self.model, self.cfg = model, cfg
        for p in self.model.parameters():
            p.requires_grad_(False)
        sk = Skeleton.from_asset(asset)
        self.sk = SkeletonBatch([sk], device=device)
        self.rest = torch.as_tensor(sk.rest_rotations, dtype=torch.float32, device=device)  # (J, 4)
        self.length = int(cfg.length)
        self.step = float(video_fps) / float(cfg.fps) if video_fps and video_fps > 0 else 1.0

    @property
    def span(self) -> int:
        """Video frames one window covers."""
        return int(math.floor((self.length - 1) * self.step + 1e-6)) + 1

    def window(self, frames: Tensor, num_frames: int) -> Tensor:
        """(L,) video frame indices of the window centred on ``frames`` (a step's frames), kept
        inside the video; a video shorter than a window repeats its last frame."""
        centre = 0.5 * (float(frames.min()) + float(frames.max()))
        start = min(max(centre - 0.5 * (self.span - 1), 0.0), max(num_frames - self.span, 0))
        idx = torch.round(start + torch.arange(self.length, device=frames.device) * self.step).long()
        return idx.clamp_(0, num_frames - 1)

    def loss(self, rotations: Tensor, frames: Tensor) -> Tensor:
        """The negative ELBO (scalar) of the window around ``frames`` (indices into the video) of
        the local joint rotations (T, J, 4) wxyz (the template's rest rotations included)."""
        return self.terms(rotations, frames)["total"]

    def terms(self, rotations: Tensor, frames: Tensor) -> dict[str, Tensor]:
        """`loss` as ``total`` with its terms ``rotation``, ``joints`` and ``kl``."""
        q = quat_normalize(rotations[self.window(frames, rotations.shape[0])])
        delta = quat_mul(quat_conjugate(self.rest).to(q.dtype)[None], q)
        target = quat_to_matrix(delta).float()[None]  # (1, L, J, 3, 3)
        mu, logvar = self.model.encode(matrix_to_rot6d(target), self.sk)
        pred = rot6d_to_matrix(self.model.decode(mu, self.sk))
        rot = rotation_loss(pred, target, self.sk.mask)
        joints = joint_loss(self.sk.joint_positions(pred), self.sk.joint_positions(target), self.sk.mask)
        kl = kl_loss(mu, logvar)
        total = self.cfg.rot_weight * rot + self.cfg.joint_weight * joints + self.cfg.kl_weight * kl
        return {"total": total, "rotation": rot, "joints": joints, "kl": kl}
