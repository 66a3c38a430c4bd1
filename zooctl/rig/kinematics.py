"""Forward kinematics over a joint tree, batched over frames (and animals) in PyTorch.

A joint's model transform is its parent's times its local transform ``T @ R @ S`` (the asset
convention). FK runs by pointer jumping: each round multiplies every joint's transform by that of
the ancestor it reaches so far, which then reaches twice as far, so a tree of depth d takes
ceil(log2(d + 1)) rounds of two batched operators (4 for a 14-deep animal, not 14 levels of three):
the operator count, what a GPU pays for in launches, grows with the log of the depth.
"""

from __future__ import annotations

import numpy as np
import torch

from .rotations import quat_to_matrix

Tensor = torch.Tensor


class KinematicTree:
    """The pointer-jumping schedule of a ``parents`` array (``parents[j] < j``, roots ``-1``).

    ``jumps[r]`` (J + 1,) is the ancestor each joint multiplies by in round ``r`` (index J: an
    identity past the roots, which it maps to itself).
    """

    def __init__(self, parents: np.ndarray | list[int], device: torch.device | str | None = None):
        parents = np.asarray(parents, dtype=np.int64)
        if (parents >= np.arange(len(parents))).any():
            raise ValueError("parents must be topologically sorted (parents[j] < j)")
        self.parents = parents
        self.num_joints = J = len(parents)
        reach = np.append(np.where(parents < 0, J, parents), J)  # (J + 1,): J is past the roots
        jumps = []
        while (reach[:J] != J).any():
            jumps.append(reach.copy())
            reach = reach[reach]
        self.jumps = [torch.as_tensor(r, device=device) for r in jumps]

    def to(self, device: torch.device | str) -> KinematicTree:
        self.jumps = [r.to(device) for r in self.jumps]
        return self


def compose_trs(translation: Tensor, rotation: Tensor, scale: Tensor | None = None) -> Tensor:
    """Local transforms ``T @ R @ S``.

    translation (..., 3), rotation (..., 4) wxyz, scale (..., 3) or None -> (..., 4, 4).
    """
    r = quat_to_matrix(rotation)
    if scale is not None:
        r = r * scale[..., None, :]
    top = torch.cat((r, translation[..., :, None]), -1)  # (..., 3, 4)
    bottom = top.new_zeros(top.shape[:-2] + (1, 4))
    bottom[..., 0, 3] = 1.0
    return torch.cat((top, bottom), -2)


def forward_kinematics(local: Tensor, tree: KinematicTree) -> Tensor:
    """Joint-to-model transforms.

    local: (..., J, 4, 4) local transforms; returns (..., J, 4, 4) with
    ``G[j] = G[parents[j]] @ local[j]`` (roots: ``G[j] = local[j]``), by pointer jumping
    (module docstring; the products associate differently from level by level, so the two agree
    to float rounding).
    """
    if not tree.jumps:
        return local
    eye = torch.eye(4, dtype=local.dtype, device=local.device).expand(*local.shape[:-3], 1, 4, 4)
    g = torch.cat((local, eye), -3)
    for reach in tree.jumps:
        g = g.index_select(-3, reach) @ g  # index_select: a backward without sorting
    return g[..., :-1, :, :]
