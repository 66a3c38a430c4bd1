"""Motion metrics on normalised joint positions (units: percent of the skeleton's rest diagonal,
root motion excluded, so positions are in the body frame).

Every function takes windows of joint positions P (N, T, J, 3) from `joint_positions`.
"""

from __future__ import annotations

import numpy as np
import torch

from ..geometry import quat_to_matrix
from .skeleton import Skeleton, SkeletonBatch


def joint_positions(windows: np.ndarray, skeleton: Skeleton) -> np.ndarray:
    """Rest-relative rotations (N, T, J, 4) -> joint positions (N, T, J, 3) in % of skeleton size."""
    if len(windows) == 0:
        return np.zeros(windows.shape[:3] + (3,))
    sk = SkeletonBatch([skeleton]).take([0] * len(windows))
    with torch.no_grad():
        pos = sk.joint_positions(torch.as_tensor(quat_to_matrix(windows), dtype=torch.float32))
    return 100.0 * pos.double().numpy()


def mpjpe(a: np.ndarray, b: np.ndarray) -> float:
    """Mean per-joint position error between paired windows (N, T, J, 3)."""
    return float(np.linalg.norm(a - b, axis=-1).mean())


def rotation_error_deg(qa: np.ndarray, qb: np.ndarray) -> float:
    """Mean geodesic angle in degrees between paired unit quaternions (..., 4)."""
    d = np.abs((qa * qb).sum(-1)).clip(max=1.0)
    return float(np.degrees(2 * np.arccos(d)).mean())


def pairwise_mse(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(Na, Nb) mean squared joint-position distance between every window of a and of b."""
    fa, fb = a.reshape(len(a), -1), b.reshape(len(b), -1)
    d = (fa**2).sum(1)[:, None] + (fb**2).sum(1)[None] - 2 * fa @ fb.T
    return np.maximum(d, 0.0) / (fa.shape[1] / 3)


def motion_chamfer(gen: np.ndarray, real: np.ndarray) -> float:
    """Ponymation's MCD in 3D joint space: bidirectional nearest-sequence joint-position MSE, averaged."""
    d = pairwise_mse(gen, real)
    return float(0.5 * (d.min(1).mean() + d.min(0).mean()))


def diversity(samples: np.ndarray) -> float:
    """Mean pairwise distance of samples (mean per-joint L2 over frames), over all pairs."""
    n = len(samples)
    if n < 2:
        return 0.0
    tot, cnt = 0.0, 0
    for i in range(n - 1):
        tot += float(np.linalg.norm(samples[i + 1 :] - samples[i], axis=-1).mean(axis=(1, 2)).sum())
        cnt += n - 1 - i
    return tot / cnt


def smoothness(p: np.ndarray) -> float:
    """Mean joint acceleration magnitude |p[t+1] - 2 p[t] + p[t-1]| (per frame squared); lower is smoother."""
    if p.shape[1] < 3:
        return 0.0
    return float(np.linalg.norm(p[:, 2:] - 2 * p[:, 1:-1] + p[:, :-2], axis=-1).mean())


def foot_sliding(p: np.ndarray, feet: np.ndarray, contact: float = 2.0) -> float | None:
    """Mean horizontal foot speed (per frame) while a foot is in contact: both frames within
    ``contact`` (% of size) of the lowest height of that foot in the window. None without feet."""
    if len(feet) < 2 or p.shape[1] < 2:
        return None
    f = p[:, :, feet]  # (N, T, F, 3)
    y = f[..., 1]
    ground = y.min(1, keepdims=True)
    touch = y <= ground + contact
    both = touch[:, 1:] & touch[:, :-1]
    speed = np.linalg.norm((f[:, 1:] - f[:, :-1])[..., [0, 2]], axis=-1)
    return float(speed[both].mean()) if both.any() else 0.0


# -- metrics that catch a statue: how far and how fast joints turn, gait, seams ----------------


def _angle_deg(qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
    """Geodesic angle in degrees between unit quaternions (..., 4) -> (...)."""
    return np.degrees(2 * np.arccos(np.abs((qa * qb).sum(-1)).clip(max=1.0)))


def joint_amplitude(q: np.ndarray) -> np.ndarray:
    """Per joint, how far it turns away from its first pose: rest-relative rotations (N, T, J, 4)
    -> (J,) degrees, the largest angle to frame 0 in each window, averaged over windows."""
    return _angle_deg(q, q[:, :1]).max(1).mean(0)


def joint_speed(q: np.ndarray) -> np.ndarray:
    """Per joint, how fast it turns: (N, T, J, 4) -> (J,) mean degrees per frame."""
    if q.shape[1] < 2:
        return np.zeros(q.shape[2])
    return _angle_deg(q[:, 1:], q[:, :-1]).mean((0, 1))


def motion_ratio(gen: np.ndarray, real: np.ndarray) -> float | None:
    """Per-joint motion (J,) of samples over that of real windows, summed over joints (so the
    joints that move in the data weigh most): 1 moves like the data, ~0 is a statue."""
    total = float(np.sum(real))
    return float(np.sum(gen)) / total if total > 1e-9 else None


def gait_periodicity(p: np.ndarray, feet: np.ndarray, min_lag: int = 5) -> float | None:
    """How periodic the feet move, in [-1, 1]: the highest normalised autocorrelation of the feet's
    vertical velocities at a lag of ``min_lag`` frames to two thirds of the window, averaged over
    windows (velocities, not heights: a slow drift of the heights correlates at any lag). A walk
    or trot scores ~0.5-1, a statue or a random drift ~0. p (N, T, J, 3); None without feet."""
    if len(feet) < 2 or p.shape[1] < 3 * min_lag + 1:
        return None
    y = np.diff(p[:, :, feet, 1], axis=1)  # (N, T-1, F)
    T = y.shape[1]
    best = np.full(len(p), -1.0)
    for lag in range(min_lag, T - T // 3 + 1):
        num = (y[:, lag:] * y[:, :-lag]).sum((1, 2))
        a = np.sqrt((y[:, lag:] ** 2).sum((1, 2)) * (y[:, :-lag] ** 2).sum((1, 2)))
        best = np.maximum(best, np.where(a > 1e-12, num / np.maximum(a, 1e-12), 0.0))
    best = np.where((y**2).sum((1, 2)) > 1e-9, best, 0.0)  # feet that never move have no gait
    return float(best.mean())


def frame_jumps(p: np.ndarray) -> np.ndarray:
    """Change of joint velocity between frames, mean over joints: p (N, T, J, 3) -> (N, T-2)
    |v[t] - v[t-1]| at frames 1..T-2 (a seam shows as a spike)."""
    v = p[:, 1:] - p[:, :-1]
    return np.linalg.norm(v[:, 1:] - v[:, :-1], axis=-1).mean(-1)


def seam_jump(p: np.ndarray, seams: list[int]) -> float | None:
    """Mean velocity change at the given seam frames (between frame s-1 and s) of chained samples
    (N, T, J, 3); compare with the data's 95th percentile of `frame_jumps`."""
    j = frame_jumps(p)  # j[:, i] is the change at frame i + 1
    idx = [i for s in seams for i in (s - 2, s - 1) if 0 <= i < j.shape[1]]
    return float(j[:, idx].mean()) if idx else None
