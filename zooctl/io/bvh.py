"""BVH (Biovision hierarchy): the skeleton and its motion, what motion-capture tools read.

Writing. ``HIERARCHY`` holds each joint's rest offset from its parent (``OFFSET``, the rest local
translation, in the asset's units); ``MOTION`` one line per frame. BVH has no rest rotation, so a
joint's channels carry its whole local rotation, as Euler angles in degrees in the order
``Zrotation Xrotation Yrotation`` (R = Rz Rx Ry, the CMU convention). The root, and any joint whose
translation is animated, also has ``Xposition Yposition Zposition`` channels. Scales cannot be
written (BVH has none) and are dropped; leaves end in a zero-length ``End Site``. Several clips
(same fps) are written one after the other; a skeleton with several roots gets one extra root.

`read_bvh` reads what `save_bvh` writes (and ordinary BVH files) back into offsets, channels and
per-frame local transforms, which the tests compare with the asset's own forward kinematics.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..asset import RiggedAsset
from ..errors import InputError, UsageError
from ..store.fs import write_bytes_atomic

ROT = ("Zrotation", "Xrotation", "Yrotation")
POS = ("Xposition", "Yposition", "Zposition")
EXTRA_ROOT = "zooctl_root"


def _euler_zxy(q: np.ndarray) -> np.ndarray:
    """(..., 4) wxyz -> (..., 3) degrees (z, x, y) with R = Rz Rx Ry."""
    from scipy.spatial.transform import Rotation

    flat = q.reshape(-1, 4)
    r = Rotation.from_quat(np.concatenate((flat[:, 1:], flat[:, :1]), 1))
    return r.as_euler("ZXY", degrees=True).reshape(q.shape[:-1] + (3,))


def _motion(asset: RiggedAsset, clips: Sequence[str] | None) -> tuple[np.ndarray, np.ndarray, float]:
    """Concatenated local rotations (T, J, 4), translations (T, J, 3) and the fps."""
    names = list(asset.clips) if clips is None else list(clips)
    for c in names:
        if c not in asset.clips:
            raise UsageError(
                f"asset {asset.name!r} has no clip {c!r}", hint=f"clips: {', '.join(asset.clips)}"
            )
    if not names:  # no motion: one frame of the rest pose
        _, q, _ = asset.rest_trs()
        t = asset.rest_local[:, :3, 3]
        return q[None], t[None], 30.0
    fps = {float(asset.clips[c].fps) for c in names}
    if len(fps) > 1:
        raise UsageError(
            f"BVH holds one frame rate, but the clips {', '.join(names)} have {sorted(fps)}",
            hint="export one clip at a time with --clip",
        )
    rot = np.concatenate([asset.clips[c].rotations for c in names]).astype(np.float64)
    trans = np.concatenate([asset.clips[c].translations for c in names]).astype(np.float64)
    return rot, trans, fps.pop()


def bvh_text(asset: RiggedAsset, clips: Sequence[str] | None = None) -> str:
    """The BVH file for ``asset`` and the named ``clips`` (all by default), as text."""
    rot, trans, fps = _motion(asset, clips)
    parents = [int(p) for p in asset.parents]
    offsets = asset.rest_local[:, :3, 3].astype(np.float64)
    children: dict[int, list[int]] = {j: [] for j in range(-1, len(parents))}
    for j, p in enumerate(parents):
        children[p].append(j)
    moving = np.ptp(trans, axis=0).max(-1) > 1e-6 * max(asset.size(), 1e-9)  # (J,)
    euler = _euler_zxy(rot)  # (T, J, 3)
    fmt = lambda v: " ".join(f"{x:.6f}" for x in v)  # noqa: E731
    lines: list[str] = ["HIERARCHY"]
    columns: list[np.ndarray] = []  # one (T, k) block per joint, in file order
    roots = children[-1]
    extra = len(roots) > 1

    def joint(j: int, depth: int, root: bool) -> None:
        pad = "\t" * depth
        lines.append(f"{pad}{'ROOT' if root else 'JOINT'} {asset.joint_names[j]}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}\tOFFSET {fmt(offsets[j])}")
        if root or moving[j]:
            lines.append(f"{pad}\tCHANNELS 6 {' '.join(POS + ROT)}")
            columns.append(np.concatenate((trans[:, j], euler[:, j]), 1))
        else:
            lines.append(f"{pad}\tCHANNELS 3 {' '.join(ROT)}")
            columns.append(euler[:, j])
        for c in children[j]:
            joint(c, depth + 1, False)
        if not children[j]:
            lines.extend([f"{pad}\tEnd Site", f"{pad}\t{{", f"{pad}\t\tOFFSET 0 0 0", f"{pad}\t}}"])
        lines.append(f"{pad}}}")

    if extra:
        lines += [f"ROOT {EXTRA_ROOT}", "{", "\tOFFSET 0 0 0", f"\tCHANNELS 6 {' '.join(POS + ROT)}"]
        columns.append(np.zeros((len(rot), 6)))
        for r in roots:
            joint(r, 1, False)
        lines.append("}")
    else:
        joint(roots[0], 0, True)
    table = np.concatenate(columns, 1)
    lines += ["MOTION", f"Frames: {len(table)}", f"Frame Time: {1.0 / fps:.8f}"]
    lines += [fmt(row) for row in table]
    return "\n".join(lines) + "\n"


def save_bvh(asset: RiggedAsset, path: str | Path, clips: Sequence[str] | None = None) -> Path:
    """Write ``asset``'s skeleton and motion as a ``.bvh`` file, atomically."""
    path = Path(path)
    if path.suffix.lower() != ".bvh":
        raise UsageError(f"cannot write BVH to {path.name!r}", hint="use a .bvh file name")
    write_bytes_atomic(path, bvh_text(asset, clips).encode())
    return path


@dataclass
class Bvh:
    """A parsed BVH file: joint names and parents (file order), offsets (J, 3), each joint's
    channel names, the frame time and the channel values (T, C)."""

    names: list[str]
    parents: list[int]
    offsets: np.ndarray
    channels: list[tuple[str, ...]]
    frame_time: float
    motion: np.ndarray

    def local_matrices(self) -> np.ndarray:
        """(T, J, 4, 4) local transforms: T(offset or position channels) R(rotation channels)."""
        from scipy.spatial.transform import Rotation

        T, J = len(self.motion), len(self.names)
        out = np.tile(np.eye(4), (T, J, 1, 1))
        col = 0
        for j, chans in enumerate(self.channels):
            vals = self.motion[:, col : col + len(chans)]
            col += len(chans)
            pos = self.offsets[j][None].repeat(T, 0)
            rot_axes, rot_vals = "", []
            for k, c in enumerate(chans):
                if c in POS:
                    pos[:, POS.index(c)] = vals[:, k]
                else:
                    rot_axes += c[0].upper()
                    rot_vals.append(vals[:, k])
            out[:, j, :3, 3] = pos
            if rot_axes:
                out[:, j, :3, :3] = Rotation.from_euler(
                    rot_axes, np.stack(rot_vals, 1), degrees=True
                ).as_matrix()
        return out

    def global_matrices(self) -> np.ndarray:
        """(T, J, 4, 4) joint-to-world transforms."""
        local = self.local_matrices()
        glob = np.empty_like(local)
        for j, p in enumerate(self.parents):
            glob[:, j] = local[:, j] if p < 0 else glob[:, p] @ local[:, j]
        return glob


def read_bvh(path: str | Path) -> Bvh:
    """Parse a BVH file; a malformed one is an `InputError` naming the problem."""
    tokens = Path(path).read_text().split()
    names: list[str] = []
    parents: list[int] = []
    offsets: list[list[float]] = []
    channels: list[tuple[str, ...]] = []
    stack: list[int] = []
    i = 0
    try:
        if tokens[0] != "HIERARCHY":
            raise ValueError("no HIERARCHY")
        i = 1
        while tokens[i] != "MOTION":
            tok = tokens[i]
            if tok in ("ROOT", "JOINT"):
                names.append(tokens[i + 1])
                parents.append(stack[-1] if stack else -1)
                i += 2
            elif tok == "End":
                names.append(None)  # type: ignore[arg-type]  (an end site: not a joint)
                parents.append(stack[-1])
                i += 2
            elif tok == "{":
                stack.append(len(names) - 1)
                i += 1
            elif tok == "}":
                stack.pop()
                i += 1
            elif tok == "OFFSET":
                offsets.append([float(x) for x in tokens[i + 1 : i + 4]])
                i += 4
            elif tok == "CHANNELS":
                n = int(tokens[i + 1])
                channels.append(tuple(tokens[i + 2 : i + 2 + n]))
                i += 2 + n
            else:
                raise ValueError(f"unexpected {tok!r}")
        frames = int(tokens[i + 2])
        frame_time = float(tokens[i + 5])
        values = np.array([float(x) for x in tokens[i + 6 :]])
    except (IndexError, ValueError) as exc:
        raise InputError(f"{path}: not a valid BVH file ({exc})") from None
    keep = [k for k, n in enumerate(names) if n is not None]
    remap = {k: n for n, k in enumerate(keep)}
    C = sum(len(c) for c in channels)
    if values.size != frames * C:
        raise InputError(f"{path}: {values.size} motion values for {frames} frames of {C} channels")
    return Bvh(
        [names[k] for k in keep],
        [remap.get(parents[k], -1) for k in keep],
        np.array([offsets[k] for k in keep]),
        channels,
        frame_time,
        values.reshape(frames, C),
    )
