"""Building a skeleton joint by joint from bind-pose positions.

Procedural animals are rigged in a pose where every joint frame is aligned with the model axes
(rest rotations are the identity), so a local rest transform is a pure translation from the parent
joint and the inverse bind matrix of joint k is a translation by ``-position[k]``.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError


class SkeletonBuilder:
    """Collects joints in topological order (a parent is always added before its children)."""

    def __init__(self) -> None:
        self.names: list[str] = []
        self.parent_index: list[int] = []
        self.positions: list[np.ndarray] = []

    def add(self, name: str, position: np.ndarray | list[float], parent: str | None = None) -> str:
        """Add joint ``name`` at bind-space ``position`` (3,) under ``parent`` (``None``: a root)."""
        if name in self.names:
            raise InputError(f"joint {name!r} added twice")
        p = -1 if parent is None else self.index(parent)
        self.names.append(name)
        self.parent_index.append(p)
        self.positions.append(np.asarray(position, dtype=np.float64).reshape(3))
        return name

    def chain(self, names: list[str], points: np.ndarray, parent: str | None) -> list[str]:
        """Add a chain of joints ``names[i]`` at ``points[i]`` (N, 3), each the child of the previous."""
        for name, p in zip(names, points, strict=True):
            parent = self.add(name, p, parent)
        return names

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise InputError(f"unknown joint {name!r}") from None

    def position(self, name: str) -> np.ndarray:
        return self.positions[self.index(name)]

    def arrays(self) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(names, parents (J,), positions (J, 3), rest_local (J, 4, 4), inverse_bind (J, 4, 4))."""
        parents = np.asarray(self.parent_index, dtype=np.int32)
        pos = np.stack(self.positions)
        J = len(self.names)
        rest = np.tile(np.eye(4), (J, 1, 1))
        rest[:, :3, 3] = pos - np.where(parents[:, None] >= 0, pos[np.maximum(parents, 0)], 0.0)
        inv_bind = np.tile(np.eye(4), (J, 1, 1))
        inv_bind[:, :3, 3] = -pos
        return list(self.names), parents, pos, rest, inv_bind
