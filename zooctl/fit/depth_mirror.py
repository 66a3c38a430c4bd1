"""The depth mirror of a camera start, and the camera's elevation over the animal.

A view of an animal and its mirror in depth cast the same silhouette; `zooctl.fit.view_trial`
says when a fit tries both, `fit_video` (``start="mirror"``) starts from the mirror.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..geometry import matrix_to_quat, quat_to_matrix
from .camera_init import CameraInit


def view_elevation(root_rotation: np.ndarray) -> float:
    """Mean elevation in degrees of the camera over the template's horizon (zooctl's templates
    are Y up): positive when the camera looks down on the animal. root_rotation (T, 4) wxyz, the
    fit's camera looking down -Z."""
    R = quat_to_matrix(np.asarray(root_rotation, np.float64))  # (T, 3, 3)
    up_towards_camera = float(np.mean(R[:, 2, 1]))
    return math.degrees(math.asin(min(max(up_towards_camera, -1.0), 1.0)))


def depth_mirror(init: CameraInit, rest: np.ndarray, normal: np.ndarray, offset: float) -> CameraInit:
    """``init`` with every frame's animal mirrored in depth through its own centre.

    rest (V, 3) the template's rest vertices; (normal (3,), offset) its mirror plane
    ``normal . x = offset``. A frame's vertices ``R x + t`` become ``M_z (R x + t)`` mirrored
    about the depth of the animal's centre; with ``x = S x' + 2 offset normal`` (the template is
    its own mirror image) that is root rotation ``M_z R S`` and a new translation."""
    n = np.asarray(normal, np.float64)
    S = np.eye(3) - 2.0 * np.outer(n, n)
    Mz = np.diag([1.0, 1.0, -1.0])
    R = quat_to_matrix(np.asarray(init.root_rotation, np.float64))  # (T, 3, 3)
    t = np.asarray(init.root_translation, np.float64)  # (T, 3)
    centre_z = (R @ np.asarray(rest, np.float64).mean(0) + t)[:, 2]
    rot = Mz @ R @ S
    trans = t * np.array([1.0, 1.0, -1.0])
    trans[:, 2] += 2.0 * centre_z
    trans += 2.0 * float(offset) * (Mz @ R @ n)
    return replace(init, root_rotation=np.stack([matrix_to_quat(r) for r in rot]), root_translation=trans)
