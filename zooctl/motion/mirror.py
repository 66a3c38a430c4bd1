"""Left-right mirrored motions: data augmentation for the motion prior.

A walk that starts on the left foot, mirrored, is a walk that starts on the right: a motion the
animal makes and a clip may not hold. Mirroring needs to know which joints are each other's
mirror image. Rest poses of artist rigs are rarely symmetric enough to pair joints by position,
but their names say it (``FrontLeg.L`` / ``FrontLeg.R``, ``LeftArm`` / ``RightArm``,
``l_wing`` / ``r_wing``), so joints are paired by name; a skeleton without named pairs is not
mirrored.

Each joint's rotation is mirrored in model space: its change from the rest orientation,
``D_j = A_j A_rest_j^-1`` (A: the joint's global orientation), is reflected through the
skeleton's mirror plane (``M D M``, a rotation again) and given to its mirror joint, whose local
rotation is then solved through the tree. The mirror plane's normal is the mean left-right
offset of the paired rest joints.
"""

from __future__ import annotations

import re

import numpy as np

from ..geometry import compose_trs, global_transforms, quat_mul, quat_normalize
from .dataset import MotionSequence, quat_conj
from .skeleton import Skeleton

# (pattern, swap): a side marker as a token of its own in the name, and what it becomes mirrored.
_SIDES = (
    (r"(?<=[._\-\s])([LlRr])(?=$|[._\-\s\d])", {"L": "R", "R": "L", "l": "r", "r": "l"}),
    (r"^([LlRr])(?=[._\-\s])", {"L": "R", "R": "L", "l": "r", "r": "l"}),
    (
        r"(Left|Right|left|right|LEFT|RIGHT)",
        {
            "Left": "Right",
            "Right": "Left",
            "left": "right",
            "right": "left",
            "LEFT": "RIGHT",
            "RIGHT": "LEFT",
        },
    ),
)


def _swapped(name: str) -> list[str]:
    out = []
    for pattern, swap in _SIDES:
        for m in re.finditer(pattern, name):
            s = m.group(1)
            out.append(name[: m.start(1)] + swap[s] + name[m.end(1) :])
    return out


def mirror_pairs(joint_names: list[str]) -> np.ndarray:
    """(J,) the index of each joint's mirror joint, by name; a joint without a partner (the spine,
    the head, or a side joint whose partner is misnamed) is its own mirror."""
    index = {n: j for j, n in enumerate(joint_names)}
    out = np.arange(len(joint_names))
    for j, name in enumerate(joint_names):
        for other in _swapped(name):
            k = index.get(other)
            if k is not None and k != j:
                out[j] = k
                break
    # Keep only consistent pairs (j <-> k both ways).
    bad = out[out] != np.arange(len(out))
    out[bad] = np.nonzero(bad)[0]
    return out


def _rest_globals(sk: Skeleton) -> tuple[np.ndarray, np.ndarray]:
    """(J, 4) global rest orientations and (J, 3) rest joint positions in model space."""
    J = sk.num_joints
    A = np.zeros((J, 4))
    for j, p in enumerate(sk.parents):
        A[j] = sk.rest_rotations[j] if p < 0 else quat_mul(A[p], sk.rest_rotations[j])
    local = compose_trs(sk.rest_translations, sk.rest_rotations, sk.rest_scales)
    pos = global_transforms(local, sk.parents)[:, :3, 3]
    return quat_normalize(A), pos


def mirror_plane_normal(sk: Skeleton, pairs: np.ndarray) -> np.ndarray | None:
    """(3,) unit normal of the skeleton's left-right mirror plane from its paired rest joints, or
    None without pairs (or with pairs that sit on top of each other)."""
    _, pos = _rest_globals(sk)
    js = np.nonzero(pairs > np.arange(len(pairs)))[0]
    if len(js) == 0:
        return None
    d = pos[js] - pos[pairs[js]]
    # The pairs may be listed either way round: align every offset with the largest one.
    ref = d[np.argmax(np.linalg.norm(d, axis=1))]
    d = d * np.where(d @ ref < 0, -1.0, 1.0)[:, None]
    n = d.sum(0)
    norm = float(np.linalg.norm(n))
    return None if norm < 1e-9 else n / norm


def reflect_quat(q: np.ndarray, n: np.ndarray) -> np.ndarray:
    """(..., 4) the rotation ``M R M`` for rotations q (..., 4) wxyz and the reflection
    M = I - 2 n n^T (n (3,) unit): the same angle about the reflected axis, turned the other way."""
    v = q[..., 1:]
    mv = v - 2.0 * (v @ n)[..., None] * n
    return np.concatenate([q[..., :1], -mv], -1)


def mirror_sequence(seq: MotionSequence) -> MotionSequence | None:
    """The left-right mirror of a motion (module docstring), or None for a skeleton without named
    left/right joints."""
    sk = seq.skeleton
    pairs = mirror_pairs(sk.joint_names)
    if np.all(pairs == np.arange(len(pairs))):
        return None
    n = mirror_plane_normal(sk, pairs)
    if n is None:
        return None
    A_rest, _ = _rest_globals(sk)
    local = seq.local_rotations()  # (T, J, 4)
    A = np.zeros_like(local)
    for j, p in enumerate(sk.parents):
        A[:, j] = local[:, j] if p < 0 else quat_mul(A[:, p], local[:, j])
    D = quat_mul(A, quat_conj(A_rest)[None])  # change of each joint's orientation from rest
    D_m = reflect_quat(D[:, pairs], n)  # the mirror joint's change, reflected
    A_m = quat_mul(D_m, np.broadcast_to(A_rest, D_m.shape))
    local_m = np.zeros_like(local)
    for j, p in enumerate(sk.parents):
        local_m[:, j] = A_m[:, j] if p < 0 else quat_mul(quat_conj(A_m[:, p]), A_m[:, j])
    delta = quat_mul(quat_conj(sk.rest_rotations)[None], quat_normalize(local_m))
    # Keep one hemisphere per joint, as the source does (q and -q are the same rotation).
    delta = quat_normalize(delta)
    delta *= np.where(delta[..., :1] < 0, -1.0, 1.0)
    return MotionSequence(f"{seq.name} (mirrored)", sk, delta, seq.fps, seq.source)
