"""Procedural animation clips: gaits, swimming, slithering, flapping and idling, as looping cycles.

Procedural skeletons have identity rest rotations, so every joint frame is aligned with the model
axes at rest (Y up, -Z forward, the animal's right is +X) and a rotation axis written in model
coordinates is the joint's local axis too. A clip is built by composing small rotations on top of
the rest pose, each a function of the cycle phase, so that the last frame flows into the first.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..asset import Clip
from ..geometry import decompose_trs, quat_mul

FPS = 30.0


@dataclass(frozen=True)
class Limb:
    """A leg, arm or wing for the gait generators.

    joints: root-to-tip joint names (at least two); phase: offset in cycles [0, 1);
    swing_axis: rotation axis (3,) of ``joints[0]`` whose positive angle moves the limb forward;
    lift_axis: axis (3,) of ``joints[0]`` whose positive angle lifts it (None: lift by bending);
    bend_axis: axis (3,) of ``joints[1]`` whose positive angle folds the limb while it swings.
    """

    joints: tuple[str, ...]
    phase: float
    swing_axis: tuple[float, float, float]
    lift_axis: tuple[float, float, float] | None = None
    bend_axis: tuple[float, float, float] | None = None


def axis_angle_quat(axis: np.ndarray | tuple[float, ...], angle: np.ndarray) -> np.ndarray:
    """(T,) angles about one axis (3,) -> (T, 4) wxyz."""
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    half = 0.5 * np.asarray(angle, dtype=np.float64)
    return np.concatenate([np.cos(half)[:, None], np.sin(half)[:, None] * a[None]], axis=1)


class ClipBuilder:
    """Accumulates per-joint rotations and root offsets over ``frames`` frames of one cycle.

    ``phase`` (T,) runs over [0, 1) so sin(2*pi*phase) loops seamlessly.
    """

    def __init__(self, joint_names: list[str], rest_local: np.ndarray, frames: int, fps: float = FPS):
        self.names = joint_names
        self.frames = frames
        self.fps = fps
        t, _, s = decompose_trs(rest_local)
        self.translations = np.repeat(t[None], frames, axis=0)
        self.scales = np.repeat(s[None], frames, axis=0)
        self.rotations = np.zeros((frames, len(joint_names), 4))
        self.rotations[..., 0] = 1.0
        self.phase = np.arange(frames) / frames

    def wave(self, cycles: float = 1.0, offset: float = 0.0) -> np.ndarray:
        """sin(2 pi (cycles * phase + offset)), (T,). ``cycles`` must be an integer for a loop."""
        return np.sin(2 * np.pi * (cycles * self.phase + offset))

    def rotate(self, joint: str, axis: tuple[float, ...] | np.ndarray, angle: np.ndarray) -> None:
        """Apply a rotation of ``angle`` (T,) radians about ``axis`` after the current local rotation."""
        j = self.names.index(joint)
        self.rotations[:, j] = quat_mul(self.rotations[:, j], axis_angle_quat(axis, angle))

    def translate(self, joint: str, offset: np.ndarray) -> None:
        """Add ``offset`` (T, 3) to the joint's local translation (root bob, sway)."""
        self.translations[:, self.names.index(joint)] += offset

    def clip(self, name: str) -> Clip:
        q = self.rotations / np.linalg.norm(self.rotations, axis=-1, keepdims=True)
        return Clip(
            name=name,
            fps=self.fps,
            rotations=q.astype(np.float64),
            translations=self.translations.copy(),
            scales=self.scales.copy(),
        )


def gait(b: ClipBuilder, limbs: list[Limb], swing: float, lift: float, bend: float) -> None:
    """Move every limb through one step per cycle: swing forward and back, lifting while it
    moves forward (the half of the cycle where the swing angle grows)."""
    for limb in limbs:
        sw = b.wave(1, limb.phase)
        up = np.clip(np.cos(2 * np.pi * (b.phase + limb.phase)), 0.0, None)
        b.rotate(limb.joints[0], limb.swing_axis, swing * sw)
        if limb.lift_axis is not None:
            b.rotate(limb.joints[0], limb.lift_axis, lift * up)
        if limb.bend_axis is not None and len(limb.joints) > 1:
            b.rotate(limb.joints[1], limb.bend_axis, bend * up)


def sway(
    b: ClipBuilder,
    joints: list[str],
    axis: tuple[float, ...],
    amplitude: float,
    cycles: int = 1,
    lag: float = 0.12,
    grow: float = 0.0,
) -> None:
    """A wave travelling down ``joints``: joint i turns by amplitude * (1 + grow * i) with a phase
    lag of ``lag`` cycles per joint (tails, spines, fish bodies, snakes)."""
    for i, j in enumerate(joints):
        b.rotate(j, axis, amplitude * (1.0 + grow * i) * b.wave(cycles, -lag * i))


def bob(b: ClipBuilder, root: str, height: float, cycles: int = 2, offset: float = 0.0) -> None:
    """Vertical bounce of the root, ``cycles`` times per loop."""
    off = np.zeros((b.frames, 3))
    off[:, 1] = height * b.wave(cycles, offset)
    b.translate(root, off)
