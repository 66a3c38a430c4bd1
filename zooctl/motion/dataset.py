"""Motion data: sequences of per-bone rotations from bank clips and fits, cut into windows.

A `MotionSequence` holds rotations *relative to the rest rotation* of each bone (``R_local =
R_rest @ R_delta``), so the identity is the rest pose for every skeleton. Sources:

- `sequence_from_clip`: a clip of a bank asset (imported or procedural);
- `sequence_from_fit`: a fitted video sequence given as (name, parents, rest joint positions,
  per-frame local rotations, fps), the form the fit pipeline will hand over.

`MotionDataset` resamples every sequence to one fps, adds speed-augmented copies, cuts fixed-length
windows and serves padded batches (bucketed by joint count so little compute goes to padding).
"""

from __future__ import annotations

import zlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np
import torch

from ..errors import InputError
from ..geometry import quat_mul, quat_normalize, quat_slerp, quat_to_matrix
from .skeleton import Skeleton, SkeletonBatch


def quat_conj(q: np.ndarray) -> np.ndarray:
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def matrix_to_rot6d(m: np.ndarray) -> np.ndarray:
    """(..., 3, 3) -> (..., 6): the first two columns (the convention of `zooctl.rig.rotations`)."""
    return np.concatenate([m[..., :, 0], m[..., :, 1]], -1)


@dataclass
class MotionSequence:
    """One motion: ``rotations`` (T, J, 4) wxyz relative to rest, sampled at ``fps``."""

    name: str
    skeleton: Skeleton
    rotations: np.ndarray
    fps: float
    source: str = "clip"  # clip | fit

    @property
    def num_frames(self) -> int:
        return int(self.rotations.shape[0])

    def local_rotations(self) -> np.ndarray:
        """(T, J, 4) full local rotations ``q_rest * q_delta``."""
        return quat_normalize(quat_mul(self.skeleton.rest_rotations[None], self.rotations))


def sequence_from_clip(asset, clip: str, skeleton: Skeleton | None = None) -> MotionSequence:
    """The rotations of one clip of ``asset`` relative to its rest pose (translations are dropped)."""
    if clip not in asset.clips:
        raise InputError(
            f"asset {asset.name!r} has no clip {clip!r}", hint=f"clips: {', '.join(asset.clips) or 'none'}"
        )
    sk = skeleton or Skeleton.from_asset(asset)
    c = asset.clips[clip]
    delta = quat_mul(quat_conj(sk.rest_rotations)[None], quat_normalize(c.rotations))
    return MotionSequence(f"{asset.name}/{clip}", sk, quat_normalize(delta), float(c.fps), "clip")


def sequences_from_asset(asset, clips: Sequence[str] | None = None) -> list[MotionSequence]:
    """Every clip (or the named ones) of an asset, sharing one `Skeleton`."""
    sk = Skeleton.from_asset(asset)
    return [sequence_from_clip(asset, c, sk) for c in (clips if clips is not None else list(asset.clips))]


def sequence_from_fit(
    name: str, parents: np.ndarray, rest_joint_positions: np.ndarray, local_rotations: np.ndarray, fps: float
) -> MotionSequence:
    """A fitted video sequence: parents (J,), rest joint positions (J, 3) in model space, per-frame
    local rotations (T, J, 4) wxyz relative to a rest pose with identity rotations, at ``fps``."""
    sk = Skeleton.from_joint_positions(name, parents, rest_joint_positions)
    q = np.asarray(local_rotations, dtype=np.float64)
    if q.ndim != 3 or q.shape[1:] != (sk.num_joints, 4) or len(q) == 0 or not np.all(np.isfinite(q)):
        raise InputError(
            f"fit {name!r}: local rotations must be finite (T, {sk.num_joints}, 4), got {q.shape}"
        )
    if not fps > 0:
        raise InputError(f"fit {name!r}: fps must be positive, got {fps}")
    return MotionSequence(name, sk, quat_normalize(q), float(fps), "fit")


def resample(seq: MotionSequence, fps: float) -> MotionSequence:
    """The sequence at ``fps`` (spherical interpolation between the original frames)."""
    if seq.num_frames < 2 or abs(seq.fps - fps) < 1e-9:
        return MotionSequence(seq.name, seq.skeleton, seq.rotations.copy(), fps, seq.source)
    duration = (seq.num_frames - 1) / seq.fps
    t = np.arange(int(np.floor(duration * fps + 1e-6)) + 1) * seq.fps / fps  # in source frames
    i0 = np.clip(np.floor(t).astype(int), 0, seq.num_frames - 2)
    w = (t - i0)[:, None]
    q = quat_slerp(
        seq.rotations[i0], seq.rotations[i0 + 1], np.broadcast_to(w, (len(t), seq.rotations.shape[1]))
    )
    return MotionSequence(seq.name, seq.skeleton, q, fps, seq.source)


def windows(seq: MotionSequence, length: int, stride: int) -> np.ndarray:
    """(N, length, J, 4) windows starting every ``stride`` frames (the last one flush with the end).
    Sequences shorter than ``length`` give none."""
    T = seq.num_frames
    if T < length:
        return np.zeros((0, length, seq.rotations.shape[1], 4))
    starts = list(range(0, T - length + 1, max(1, stride)))
    if starts[-1] != T - length:
        starts.append(T - length)
    return np.stack([seq.rotations[s : s + length] for s in starts])


def holdout_split(names: dict[str, list[str]], fraction: float, seed: int = 0) -> dict[str, list[str]]:
    """Held-out clip names per asset: ``round(fraction * n)`` (at least one) of each asset with two
    or more clips, chosen by a stable hash so the split never depends on order or process."""
    out: dict[str, list[str]] = {}
    if fraction <= 0:
        return out
    for asset, clips in names.items():
        if len(clips) < 2:
            continue
        k = min(len(clips) - 1, max(1, round(fraction * len(clips))))
        ranked = sorted(clips, key=lambda c: zlib.crc32(f"{seed}:{asset}/{c}".encode()))
        out[asset] = sorted(ranked[:k])
    return out


@dataclass
class Batch:
    """Padded training batch: rot6d (B, T, J, 6) targets and their skeletons (`SkeletonBatch`)."""

    rot6d: torch.Tensor
    rotmat: torch.Tensor  # (B, T, J, 3, 3)
    skeletons: SkeletonBatch
    source: list[str]
    joint_motion: torch.Tensor | None = None  # (B, J) `MotionDataset.joint_motion` of each window's skeleton


class MotionDataset:
    """Fixed-length windows of many sequences, resampled to ``fps``.

    ``speeds``: augmentation by playing each sequence at these speed factors too (1.0 always
    included); ``stride``: frames between window starts (default half the window).
    """

    def __init__(
        self,
        sequences: Sequence[MotionSequence],
        length: int = 10,
        fps: float = 30.0,
        stride: int | None = None,
        speeds: Sequence[float] = (0.8, 1.25),
    ):
        if length < 2:
            raise InputError(f"window length must be at least 2 frames, got {length}")
        self.length, self.fps = int(length), float(fps)
        stride = stride or max(1, length // 2)
        self.skeletons: list[Skeleton] = []
        key_to_id: dict[int, int] = {}
        rots, skel_ids, sources = [], [], []
        self.sequence_names: list[str] = []
        self.skipped: list[str] = []
        for seq in sequences:
            sid = key_to_id.setdefault(id(seq.skeleton), len(self.skeletons))
            if sid == len(self.skeletons):
                self.skeletons.append(seq.skeleton)
            n_before = len(rots)
            for speed in sorted({1.0, *speeds}):
                # Playing at `speed` = resampling to fps / speed while keeping the frame rate.
                r = resample(
                    MotionSequence(seq.name, seq.skeleton, seq.rotations, seq.fps * speed, seq.source),
                    self.fps,
                )
                for w in windows(r, self.length, stride):
                    rots.append(w)
                    skel_ids.append(sid)
                    sources.append(seq.source)
            (self.sequence_names if len(rots) > n_before else self.skipped).append(seq.name)
        if not rots:
            raise InputError(
                f"no motion windows of {self.length} frames in {len(sequences)} sequence(s)",
                hint="add assets with longer clips, or train with a shorter --length",
            )
        self.skel_ids = np.array(skel_ids)
        self.sources = sources
        self._rot6d = [matrix_to_rot6d(quat_to_matrix(r)).astype(np.float32) for r in rots]
        self.table = SkeletonBatch(self.skeletons)
        self.joint_motion = self._joint_motion()

    def _joint_motion(self) -> np.ndarray:
        """(S, J) per skeleton and (padded) joint: how much the joint's rotation matrix moves
        within a window (mean squared deviation from the window's mean, summed over the 9 entries),
        averaged over the skeleton's windows; 0 for padding."""
        from ..rig.rotations import rot6d_to_matrix

        out = np.zeros((len(self.skeletons), self.table.num_joints), np.float32)
        for sid, sk in enumerate(self.skeletons):
            idx = np.flatnonzero(self.skel_ids == sid)
            r = torch.as_tensor(np.stack([self._rot6d[i] for i in idx]))
            m = rot6d_to_matrix(r)  # (N, T, J, 3, 3)
            out[sid, : sk.num_joints] = (
                ((m - m.mean(1, keepdim=True)) ** 2).sum((-1, -2)).mean((0, 1)).numpy()
            )
        return out

    def __len__(self) -> int:
        return len(self._rot6d)

    @property
    def num_frames(self) -> int:
        return len(self) * self.length

    def batch(self, ids: Sequence[int], device: torch.device | str = "cpu") -> Batch:
        from ..rig.rotations import rot6d_to_matrix

        ids = np.asarray(ids)
        sk = self.table.take(self.skel_ids[ids])
        sk = sk if torch.device(device) == sk.device else _moved(sk, device)
        J = sk.num_joints
        x = np.zeros((len(ids), self.length, J, 6), np.float32)
        x[..., 0] = 1.0
        x[..., 4] = 1.0  # identity in 6D for padded joints
        for b, i in enumerate(ids):
            r = self._rot6d[i]
            x[b, :, : r.shape[1]] = r
        rot6d = torch.as_tensor(x, device=device)
        motion = torch.as_tensor(self.joint_motion[self.skel_ids[ids], :J], device=device)
        return Batch(rot6d, rot6d_to_matrix(rot6d), sk, [self.sources[i] for i in ids], motion)

    def batches(
        self, batch_size: int, rng: np.random.Generator, device: torch.device | str = "cpu"
    ) -> Iterator[Batch]:
        """One epoch of shuffled batches, bucketed: chunks of 8 batches are sorted by joint count."""
        order = rng.permutation(len(self))
        counts = np.array([s.num_joints for s in self.skeletons])[self.skel_ids]
        chunk = batch_size * 8
        groups = []
        for s in range(0, len(order), chunk):
            part = order[s : s + chunk]
            part = part[np.argsort(counts[part], kind="stable")]
            groups += [part[i : i + batch_size] for i in range(0, len(part), batch_size)]
        for g in rng.permutation(len(groups)):
            yield self.batch(groups[g], device)


def _moved(sk: SkeletonBatch, device: torch.device | str) -> SkeletonBatch:
    sk.device = torch.device(device)
    sk._to_tensors()
    return sk
