"""The fitted character as a `RiggedAsset`: what the USD and glTF exporters write.

Bind pose = the fitted rest pose: the template's rest rotations with stretched bones, scaled by
the global scale u, the displacement field (less its mean, below) folded into the vertices. The
global scale goes into each root joint's local scale, the per-frame root transform into each
root's local transform, so the asset has one clip (named ``fit``) with a sample per video frame,
root motion included:

    root local_t = T(t_root + R_root c) R(q_root) S(u) @ T(o) R(q_t) S(s)
                 = T(t_root + R_root (u o + c)) R(q_root q_t) S(u s).

The displacement field (CASA eq. 3) is added after skinning, so skinning cannot carry it
exactly. Its mean over the vertices is a translation of the whole posed mesh: it goes into the
root's translation, ``t_root + R_root c``, not into the bind-pose vertices, where it would move
the mesh off its skeleton and bend it about the wrong points. The rest, ``d(p) - c``, is folded
into the bind-pose vertices: linear blend skinning of the asset reproduces the fitted model up to
that part turning with the bones (small by design).
"""

from __future__ import annotations

import numpy as np
import torch

from ..asset import Clip, RiggedAsset, sparsify_weights
from ..geometry import compose_trs, quat_normalize
from ..geometry import quat_mul as _quat_mul
from ..rig.skinning import child_offset_shift, stretch_vectors
from .scene import FitScene


@torch.no_grad()
def fitted_asset(
    scene: FitScene, template: RiggedAsset, name: str, fps: float, meta: dict | None = None
) -> RiggedAsset:
    """The fitted character with one clip ``fit`` of ``scene.num_frames`` samples at ``fps``."""
    m = scene.model
    u = float(m.global_scale())
    rest_t = m.rest_translation.double().cpu().numpy()
    rest_q = m.rest_rotation.double().cpu().numpy()
    rest_s = m.rest_scale.double().cpu().numpy()
    parents = template.parents.astype(np.int32)
    roots = parents < 0
    shift = np.zeros_like(rest_t)
    if m.stretch:
        s = stretch_vectors(m.bone_scales(), m.heads, m.tails) * m.stretchable[:, None]
        shift = child_offset_shift(s, m.parents, m.child_e, m.inverse_bind).double().cpu().numpy()
    trans = rest_t + shift
    local_t, local_s = trans.copy(), rest_s.copy()
    local_t[roots] *= u
    local_s[roots] *= u
    rest_local = compose_trs(local_t, rest_q, local_s)
    glob = np.empty_like(rest_local)
    for j, p in enumerate(parents):
        glob[j] = rest_local[j] if p < 0 else glob[p] @ rest_local[j]
    vertices = m().vertices.double().cpu().numpy()  # rest pose, scaled, displaced
    mean_d = np.zeros(3)  # the displacement's mean: the root carries it (module docstring)
    d = m.displacement_offsets()
    if d is not None:
        mean_d = d.double().mean(0).cpu().numpy()
        vertices = vertices - mean_d
    # Per-frame locals.
    T, J = scene.num_frames, len(parents)
    q = quat_normalize(scene.rotations.double().cpu().numpy())
    rq = quat_normalize(scene.root_rotation.double().cpu().numpy())  # (T, 4)
    rt = scene.root_translation.double().cpu().numpy()  # (T, 3)
    clip_t = np.broadcast_to(trans, (T, J, 3)).copy()
    clip_s = np.broadcast_to(rest_s, (T, J, 3)).copy()
    clip_q = q.copy()
    from ..geometry import quat_to_matrix

    R_root = quat_to_matrix(rq)  # (T, 3, 3)
    for j in np.nonzero(roots)[0]:
        clip_t[:, j] = rt + np.einsum("tab,b->ta", R_root, u * trans[j] + mean_d)
        clip_q[:, j] = _quat_mul(rq, q[:, j])
        clip_s[:, j] = u * rest_s[j]
    dense = m.skin.dense(J).double().cpu().numpy()
    sj, sw = sparsify_weights(dense, 4)
    info = dict(template.meta)
    info.update({"tags": ["fitted"], "template": template.name})
    info.update(meta or {})
    asset = RiggedAsset(
        name=name,
        vertices=vertices.astype(np.float32),
        faces=template.faces.astype(np.int32),
        joint_names=list(template.joint_names),
        parents=parents,
        rest_local=rest_local,
        inverse_bind=np.linalg.inv(glob),
        skin_joints=sj,
        skin_weights=sw,
        clips={"fit": Clip("fit", float(fps), clip_q, clip_t, clip_s)},
        uvs=template.uvs,
        vertex_colors=template.vertex_colors,
        texture_png=template.texture_png,
        meta=info,
    )
    return asset.validate()
