"""What a motion model knows about a skeleton: its tree, rest pose and size, for any animal.

`Skeleton` describes one skeleton in numpy; `SkeletonBatch` pads several to a common joint count
and poses them in PyTorch (forward kinematics through `zooctl.rig.kinematics`), so one model and
one batch can mix a 8-joint fish with a 53-joint fox.

Positions a model sees are *normalised*: centred on the rest joints' bounding-box centre and
divided by its diagonal (``Skeleton.scale``), so a 50 m dinosaur and a 30 cm crab look alike.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import torch

from ..errors import InputError
from ..geometry import compose_trs, global_transforms, quat_to_matrix

STATIC_FEATURES = 3 + 3 + 1 + 3 * 16  # rest position, bone offset, leaf flag, index/depth/parent encodings


def sinusoid(x: np.ndarray, dim: int = 16, max_period: float = 256.0) -> np.ndarray:
    """Transformer-style sinusoidal encoding of integers or reals. x (...,) -> (..., dim)."""
    half = dim // 2
    freq = np.exp(-math.log(max_period) * np.arange(half) / half)
    a = np.asarray(x, dtype=np.float64)[..., None] * freq
    return np.concatenate([np.sin(a), np.cos(a)], -1)


@dataclass
class Skeleton:
    """One skeleton: tree, rest local transforms and the normalising centre and scale.

    parents (J,) with parents[j] < j; rest_translations (J, 3), rest_rotations (J, 4) wxyz and
    rest_scales (J, 3) are the rest local TRS in model units.
    """

    key: str
    joint_names: list[str]
    parents: np.ndarray
    rest_translations: np.ndarray
    rest_rotations: np.ndarray
    rest_scales: np.ndarray
    center: np.ndarray = field(init=False)
    scale: float = field(init=False)
    rest_positions: np.ndarray = field(init=False)  # (J, 3) normalised

    def __post_init__(self) -> None:
        J = len(self.joint_names)
        self.parents = np.asarray(self.parents, dtype=np.int64)
        if J == 0 or self.parents.shape != (J,) or any(not (-1 <= p < j) for j, p in enumerate(self.parents)):
            raise InputError(
                f"skeleton {self.key!r}: parents must be (J,) topologically sorted (parents[j] < j, roots -1)"
            )
        for arr, n, w in (
            (self.rest_translations, "rest translations", 3),
            (self.rest_rotations, "rest rotations", 4),
            (self.rest_scales, "rest scales", 3),
        ):
            if np.shape(arr) != (J, w) or not np.all(np.isfinite(arr)):
                raise InputError(f"skeleton {self.key!r}: {n} must be finite ({J}, {w})")
        local = compose_trs(self.rest_translations, self.rest_rotations, self.rest_scales)
        pos = global_transforms(local, self.parents)[:, :3, 3]
        lo, hi = pos.min(0), pos.max(0)
        self.center = 0.5 * (lo + hi)
        # Guard against a single joint or a degenerate skeleton: fall back to unit scale.
        diag = float(np.linalg.norm(hi - lo))
        self.scale = diag if diag > 1e-9 else 1.0
        self.rest_positions = (pos - self.center) / self.scale

    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    def depth(self) -> np.ndarray:
        d = np.zeros(self.num_joints, dtype=np.int64)
        for j, p in enumerate(self.parents):
            d[j] = 0 if p < 0 else d[p] + 1
        return d

    @cached_property
    def _static(self) -> np.ndarray:
        return self._compute_static()

    def static_features(self) -> np.ndarray:
        """(J, STATIC_FEATURES) float32 per-bone description (cached)."""
        return self._static

    def _compute_static(self) -> np.ndarray:
        """(J, STATIC_FEATURES) float32 per-bone description: rest position, offset from the
        parent, leaf flag, and sinusoidal encodings of joint index, depth and parent index."""
        J = self.num_joints
        pos = self.rest_positions
        offset = np.where(self.parents[:, None] >= 0, pos - pos[np.maximum(self.parents, 0)], 0.0)
        leaf = np.ones(J)
        leaf[self.parents[self.parents >= 0]] = 0.0
        feats = [
            pos,
            offset,
            leaf[:, None],
            sinusoid(np.arange(J)),
            sinusoid(self.depth()),
            sinusoid(self.parents + 1),
        ]
        return np.concatenate(feats, -1).astype(np.float32)

    def feet(self, height_fraction: float = 0.08) -> np.ndarray:
        """Indices of leaf joints within ``height_fraction`` of the skeleton's size above its lowest
        rest joint: the feet of a legged animal (empty for fish and snakes held off the ground)."""
        leaf = np.ones(self.num_joints, bool)
        leaf[self.parents[self.parents >= 0]] = False
        y = self.rest_positions[:, 1]
        low = y <= y.min() + height_fraction
        return np.nonzero(leaf & low)[0]

    # -- constructors ---------------------------------------------------------------------
    @classmethod
    def from_asset(cls, asset) -> Skeleton:
        """The skeleton of a `zooctl.asset.RiggedAsset` (its rest local transforms)."""
        from ..geometry import decompose_trs

        t, q, s = decompose_trs(asset.rest_local)
        return cls(asset.name, list(asset.joint_names), np.asarray(asset.parents), t, q, s)

    @classmethod
    def from_joint_positions(
        cls, key: str, parents: np.ndarray, positions: np.ndarray, joint_names: list[str] | None = None
    ) -> Skeleton:
        """A skeleton given only rest joint positions (J, 3) in model space (a fitted animal):
        identity rest rotations and unit scales, each bone's translation the offset from its parent."""
        parents = np.asarray(parents, dtype=np.int64)
        pos = np.asarray(positions, dtype=np.float64)
        J = len(parents)
        if pos.shape != (J, 3):
            raise InputError(f"rest joint positions must be ({J}, 3) for {J} parents, got {pos.shape}")
        if any(not (-1 <= p < j) for j, p in enumerate(parents)):
            raise InputError(
                f"skeleton {key!r}: parents must be topologically sorted (parents[j] < j, roots -1)"
            )
        t = np.where(parents[:, None] >= 0, pos - pos[np.maximum(parents, 0)], pos)
        q = np.zeros((J, 4))
        q[:, 0] = 1.0
        names = joint_names or [f"joint{j}" for j in range(J)]
        return cls(key, list(names), parents, t, q, np.ones((J, 3)))


class SkeletonBatch:
    """Several skeletons padded to ``J = max joints``, as tensors on one device.

    mask (B, J) bool (True: a real joint); static (B, J, STATIC_FEATURES); rest_rot (B, J, 3, 3);
    rest_t (B, J, 3) normalised translations; rest_s (B, J, 3). Padded joints are isolated roots
    with identity transforms, so forward kinematics over the whole padded batch is one call.
    ``take(ids)`` builds the batch of chosen rows (training windows index a table of skeletons).
    """

    def __init__(self, skeletons: list[Skeleton], device: torch.device | str = "cpu"):
        self.skeletons = list(skeletons)
        B = len(skeletons)
        J = max(s.num_joints for s in skeletons)
        a = {
            "count": np.array([s.num_joints for s in skeletons]),
            "static": np.zeros((B, J, STATIC_FEATURES), np.float32),
            "rest_rot": np.tile(np.eye(3, dtype=np.float32), (B, J, 1, 1)),
            "rest_t": np.zeros((B, J, 3), np.float32),
            "rest_s": np.ones((B, J, 3), np.float32),
            "parents": np.full((B, J), -1, np.int64),
            "center": np.zeros((B, 3), np.float32),
        }
        for b, s in enumerate(skeletons):
            n = s.num_joints
            a["static"][b, :n] = s.static_features()
            a["rest_rot"][b, :n] = quat_to_matrix(s.rest_rotations)
            # Scaling every translation by 1/scale scales every FK position by 1/scale.
            a["rest_t"][b, :n] = s.rest_translations / s.scale
            a["rest_s"][b, :n] = s.rest_scales
            a["parents"][b, :n] = s.parents
            a["center"][b] = s.center / s.scale
        self._arrays = a
        self.device = torch.device(device)
        self._to_tensors()

    def _to_tensors(self) -> None:
        from ..rig.kinematics import KinematicTree

        a, dev = self._arrays, self.device
        B, J = a["parents"].shape
        self.num_joints = J
        self.mask = torch.as_tensor(np.arange(J)[None] < a["count"][:, None], device=dev)
        for k in ("static", "rest_rot", "rest_t", "rest_s", "center"):
            setattr(self, k, torch.as_tensor(a[k], dtype=torch.float32, device=dev))
        offset = (np.arange(B) * J)[:, None]
        flat = np.where(a["parents"] >= 0, a["parents"] + offset, -1).reshape(-1)
        self.tree = KinematicTree(flat, device=dev)

    def take(self, ids: np.ndarray | list[int]) -> SkeletonBatch:
        """The batch of skeletons ``ids`` (repeats allowed), padded to their own maximum."""
        ids = np.asarray(ids, dtype=np.int64)
        out = object.__new__(SkeletonBatch)
        out.skeletons = [self.skeletons[i] for i in ids]
        J = int(self._arrays["count"][ids].max())
        out._arrays = {
            k: (v[ids] if k in ("count", "center") else v[ids, :J]) for k, v in self._arrays.items()
        }
        out.device = self.device
        out._to_tensors()
        return out

    def __len__(self) -> int:
        return len(self.skeletons)

    def joint_positions(self, delta_rot: torch.Tensor) -> torch.Tensor:
        """Normalised posed joint positions.

        delta_rot (B, T, J, 3, 3) rotations relative to rest -> (B, T, J, 3); padded joints sit at
        ``-center`` and must be masked by the caller.
        """
        from ..rig.kinematics import forward_kinematics

        B, T, J = delta_rot.shape[:3]
        R = self.rest_rot[:, None] @ delta_rot * self.rest_s[:, None, :, None, :]  # R_rest R_delta S
        top = torch.cat([R, self.rest_t[:, None, :, :, None].expand(B, T, J, 3, 1)], -1)
        bottom = top.new_tensor([0.0, 0.0, 0.0, 1.0]).expand(B, T, J, 1, 4)
        local = torch.cat([top, bottom], -2)  # (B, T, J, 4, 4)
        flat = local.permute(1, 0, 2, 3, 4).reshape(T, B * J, 4, 4)
        glob = forward_kinematics(flat, self.tree)[..., :3, 3]  # (T, B*J, 3)
        return glob.reshape(T, B, J, 3).permute(1, 0, 2, 3) - self.center[:, None, None]
