"""Metrics that tell a moving animal from a statue (issue 24): amplitude and speed ratios, gait
periodicity, seam jumps, on motions whose answers are known."""

from __future__ import annotations

import numpy as np

from zooctl.motion import metrics as M


def _swing(T: int = 60, J: int = 3, amp: float = 0.5, period: float = 20.0, phase: float = 0.0) -> np.ndarray:
    """(1, T, J, 4) rotations about z by amp * sin(2 pi t / period + phase) at every joint."""
    a = amp * np.sin(2 * np.pi * np.arange(T) / period + phase)
    q = np.zeros((1, T, J, 4))
    q[..., 0] = np.cos(a / 2)[:, None]
    q[..., 3] = np.sin(a / 2)[:, None]
    return q


def test_amplitude_and_speed_ratios_catch_a_statue_and_a_slow_motion():
    real = np.concatenate([_swing(phase=p) for p in (0.0, 1.0, 2.0)])
    statue = np.repeat(real[:, :1], 60, 1)
    half = np.concatenate([_swing(amp=0.25, phase=p) for p in (0.0, 1.0, 2.0)])
    assert M.motion_ratio(M.joint_amplitude(real), M.joint_amplitude(real)) == 1.0
    assert M.motion_ratio(M.joint_amplitude(statue), M.joint_amplitude(real)) < 1e-3
    assert M.motion_ratio(M.joint_speed(statue), M.joint_speed(real)) < 1e-3
    assert abs(M.motion_ratio(M.joint_amplitude(half), M.joint_amplitude(real)) - 0.5) < 0.05
    assert abs(M.motion_ratio(M.joint_speed(half), M.joint_speed(real)) - 0.5) < 0.05
    slow = np.concatenate([_swing(period=60.0, phase=p) for p in (0.0, 1.0, 2.0)])  # same reach, slower
    assert M.motion_ratio(M.joint_speed(slow), M.joint_speed(real)) < 0.5
    assert (
        M.motion_ratio(M.joint_amplitude(real), M.joint_amplitude(statue)) is None
    )  # nothing moves in "data"


def test_gait_periodicity_of_stepping_feet():
    T = 60
    t = np.arange(T)
    p = np.zeros((2, T, 3, 3))
    p[..., 0] = np.arange(3)  # joint 0 is the body, joints 1 and 2 the feet
    p[0, :, 1, 1] = np.maximum(0, np.sin(2 * np.pi * t / 15))  # feet lift every 15 frames
    p[0, :, 2, 1] = np.maximum(0, np.sin(2 * np.pi * t / 15 + np.pi))
    rng = np.random.default_rng(0)
    p[1, :, 1:, 1] = rng.normal(0, 0.3, (T, 2)).cumsum(0)  # a random drift: no rhythm
    feet = np.array([1, 2])
    assert M.gait_periodicity(p[:1], feet) > 0.9
    assert M.gait_periodicity(p[1:], feet) < 0.6
    assert M.gait_periodicity(np.zeros_like(p), feet) == 0.0  # a statue has no gait
    assert M.gait_periodicity(p, np.array([1])) is None  # one foot: not a legged animal


def test_seam_jump_sees_a_velocity_break():
    T = 40
    p = np.zeros((1, T, 2, 3))
    p[0, :, :, 0] = 0.1 * np.arange(T)[:, None]  # constant velocity: no jump anywhere
    assert M.seam_jump(p, [20]) < 1e-9
    p[0, 20:, :, 0] += 0.5  # a segment that starts elsewhere
    jumps = M.frame_jumps(p)
    assert M.seam_jump(p, [20]) > 0.2 and np.percentile(jumps, 95) < M.seam_jump(p, [20])
    assert M.seam_jump(p, []) is None
