"""Training losses of the motion VAE, masked over padded bones.

- rotation: mean squared error of rotation matrices (from the predicted 6D) over real bones;
- joints: mean squared error of normalised posed joint positions through forward kinematics
  (`SkeletonBatch.joint_positions`, i.e. `zooctl.rig.kinematics`);
- KL divergence of the posterior N(mu, sigma^2) from N(0, I), per latent dimension summed.
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


def joint_loss(pred_pos: torch.Tensor, target_pos: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """(B, T, J, 3) normalised positions -> scalar MSE over real joints."""
    return masked_mean((pred_pos - target_pos) ** 2, mask)


def kl_loss(mu: torch.Tensor, logvar: torch.Tensor) -> torch.Tensor:
    """KL(N(mu, exp(logvar)) || N(0, I)), summed over latent dimensions, mean over the batch."""
    return (-0.5 * (1 + logvar - mu**2 - logvar.exp())).sum(-1).mean()


def vae_losses(
    pred6d: torch.Tensor,
    target_mat: torch.Tensor,
    mu: torch.Tensor,
    logvar: torch.Tensor,
    sk: SkeletonBatch,
    cfg,
) -> dict[str, torch.Tensor]:
    """Every term and the weighted ``total`` (weights from the `MotionConfig` ``cfg``)."""
    pred_mat = rot6d_to_matrix(pred6d)
    rot = rotation_loss(pred_mat, target_mat, sk.mask)
    joints = joint_loss(sk.joint_positions(pred_mat), sk.joint_positions(target_mat), sk.mask)
    kl = kl_loss(mu, logvar)
    total = cfg.rot_weight * rot + cfg.joint_weight * joints + cfg.kl_weight * kl
    return {"total": total, "rotation": rot, "joints": joints, "kl": kl}
