"""What every body plan builds with: the axes, a point and unit-vector shorthand, the eyes.

The model convention: Y up, -Z forward, feet on y = 0, the animal's right towards +X.
"""

from __future__ import annotations

import numpy as np

from .body import blob_part
from .mesh import Part

X = (1.0, 0.0, 0.0)
Y = (0.0, 1.0, 0.0)
Z = (0.0, 0.0, 1.0)
EYE = np.array([0.03, 0.03, 0.035])
SIDES = (("l", -1.0), ("r", 1.0))


def v(x: float, y: float, z: float) -> np.ndarray:
    return np.array([x, y, z], dtype=np.float64)


def unit(a: np.ndarray | tuple[float, ...]) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    return a / np.linalg.norm(a)


def eyes(center: np.ndarray, across: float, radius: float, joint: str) -> list[Part]:
    """A pair of small dark eyes at ``center`` +- ``across`` on x, rigid to ``joint``."""
    return [
        blob_part(
            f"eye_{s}",
            center + v(sx * across, 0, radius),
            center + v(sx * across, 0, -radius),
            radius,
            radius,
            [joint],
            None,
            EYE,
            n=6,
            segments=8,
        )
        for s, sx in SIDES
    ]
