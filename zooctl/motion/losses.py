"""Training losses of the motion VAE, masked over padded bones.

- rotation: each real bone's squared rotation-matrix error over that bone's own motion in the
  data (`relative_rotation_loss`, the default) or one mean squared error over all bones;
- joints: mean squared error of normalised posed joint positions through forward kinematics
  (`SkeletonBatch.joint_positions`, i.e. `zooctl.rig.kinematics`);
- velocities: relative frame-to-frame error of joint positions and of rotation matrices
  (`velocity_loss`);
- KL divergence of the posterior N(mu, sigma^2) from N(0, I), per latent dimension summed; the
  term that is *optimised* uses free bits (Kingma et al. 2016): each dimension's batch-mean KL
  below ``cfg.free_bits`` nats costs nothing, so the KL cannot push every dimension to the prior
  (posterior collapse: the decoder then ignores z and every sample is the mean motion).

Scales: rotation and joint errors are per-element means (~1e-3 once trained) while the KL is a
sum over latent dimensions (hundreds of nats for an informative latent), so the paper's 1e-3 weight
alone outweighs the reconstruction terms and collapses the posterior; free bits keep it informative.
"""

from __future__ import annotations

import torch

from ..rig.rotations import rot6d_to_matrix
from .skeleton import SkeletonBatch


def masked_mean(x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Mean of x (B, T, J, ...) over the real joints of mask (B, J)."""
    m = mask[:, None].to(x.dtype)
    while m.dim() < x.dim():
        m = m[..., None]
    per = x.shape[3:].numel() if x.dim() > 3 else 1
    return (x * m).sum() / (m.sum() * x.shape[1] * per).clamp_min(1.0)


def rotation_loss(pred_mat: torch.Tensor, target_mat: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """(B, T, J, 3, 3) each -> scalar MSE over real bones."""
    return masked_mean((pred_mat - target_mat) ** 2, mask)


def relative_rotation_loss(
    pred_mat: torch.Tensor,
    target_mat: torch.Tensor,
    mask: torch.Tensor,
    motion: torch.Tensor,
    floor: float = 0.1,
) -> torch.Tensor:
    """(B, T, J, 3, 3) each, motion (B, J) each joint's within-window rotation variance in the
    data (`MotionDataset.joint_motion`) -> scalar: each joint's squared error over its own motion,
    averaged over real joints, so a tail tip turning 5 degrees counts like a hip turning 40 (about
    1 for a decoder that outputs each window's mean pose). Joints that barely move are divided by
    ``floor`` times their skeleton's mean joint motion instead of their own."""
    err = ((pred_mat - target_mat) ** 2).sum((-1, -2)).mean(1)  # (B, J)
    m = mask.to(err.dtype)
    mean = (motion * m).sum(1, keepdim=True) / m.sum(1, keepdim=True).clamp_min(1.0)
    w = m / (motion + floor * mean).clamp_min(1e-8)
    return (err * w).sum() / m.sum().clamp_min(1.0)


def joint_loss(pred_pos: torch.Tensor, target_pos: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """(B, T, J, 3) normalised positions -> scalar MSE over real joints."""
    return masked_mean((pred_pos - target_pos) ** 2, mask)


def velocity_loss(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """Error of the frame-to-frame change of (B, T, J, ...) tensors over real joints, relative to
    the target's own change: 1 for a decoder that outputs a still pose, 0 for exact motion."""
    dp, dt = pred[:, 1:] - pred[:, :-1], target[:, 1:] - target[:, :-1]
    return masked_mean((dp - dt) ** 2, mask) / masked_mean(dt**2, mask).clamp_min(1e-10)


def kl_per_dim(mu: torch.Tensor, logvar: torch.Tensor) -> torch.Tensor:
    """mu, logvar (B, Z) -> (Z,) batch-mean KL(N(mu, exp(logvar)) || N(0, 1)) per latent dimension."""
    return (-0.5 * (1 + logvar - mu**2 - logvar.exp())).mean(0)


def kl_loss(mu: torch.Tensor, logvar: torch.Tensor) -> torch.Tensor:
    """KL(N(mu, exp(logvar)) || N(0, I)), summed over latent dimensions, mean over the batch."""
    return kl_per_dim(mu, logvar).sum()


def vae_losses(
    pred6d: torch.Tensor,
    target_mat: torch.Tensor,
    mu: torch.Tensor,
    logvar: torch.Tensor,
    sk: SkeletonBatch,
    cfg,
    kl_scale: float = 1.0,
    joint_motion: torch.Tensor | None = None,
) -> dict[str, torch.Tensor]:
    """Every term and the weighted ``total`` (weights from the `MotionConfig` ``cfg``; ``kl_scale``
    in [0, 1] is the KL annealing factor). ``kl`` is the plain KL, ``active`` the number of latent
    dimensions carrying more than 0.01 nats (about 0 when the posterior has collapsed).
    ``joint_motion`` (B, J): the data's per-joint motion, needed by ``cfg.rot_loss == "relative"``."""
    pred_mat = rot6d_to_matrix(pred6d)
    if getattr(cfg, "rot_loss", "mse") == "relative" and joint_motion is not None:
        rot = relative_rotation_loss(pred_mat, target_mat, sk.mask, joint_motion)
    else:
        rot = rotation_loss(pred_mat, target_mat, sk.mask)
    pred_pos, target_pos = sk.joint_positions(pred_mat), sk.joint_positions(target_mat)
    joints = joint_loss(pred_pos, target_pos, sk.mask)
    vel_w = getattr(cfg, "velocity_weight", 0.0)
    vel = velocity_loss(pred_pos, target_pos, sk.mask) if vel_w > 0 else joints.new_zeros(())
    rvel_w = getattr(cfg, "rot_velocity_weight", 0.0)
    rvel = velocity_loss(pred_mat, target_mat, sk.mask) if rvel_w > 0 else joints.new_zeros(())
    kl_d = kl_per_dim(mu, logvar)
    kl_opt = kl_d.clamp_min(getattr(cfg, "free_bits", 0.0)).sum()
    total = (
        cfg.rot_weight * rot
        + cfg.joint_weight * joints
        + vel_w * vel
        + rvel_w * rvel
        + kl_scale * cfg.kl_weight * kl_opt
    )
    active = (kl_d.detach() > 0.01).sum().to(total.dtype)
    return {
        "total": total,
        "rotation": rot,
        "joints": joints,
        "velocity": vel,
        "rot_velocity": rvel,
        "kl": kl_d.sum(),
        "active": active,
    }
