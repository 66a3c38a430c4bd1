"""`ArticulatedModel`: an asset's articulation as one differentiable ``nn.Module``.

Learnable shape (per animal): log bone-length scales ``log b_k`` (J,), optionally log bone girths
``log g_k`` (J,), skinning-weight logits over each vertex's K candidate bones (V, K), the
displacement MLP ``V_theta`` and the log global scale ``log u``. Per-frame motion is an input:
local joint rotations, optionally local translations and scales (default: the rest pose's), and a
root rotation and translation applied on top.

Pipeline for frame t (see `zooctl.rig.skinning` for the stretch rule):

0. p_i <- p_i + sum_k w0_ik (g_k - 1) r_ik   (girth: r_ik is p_i less its nearest point on bone k,
   w0 the template's weights; a bone thickens in every direction across it, the one a silhouette
   does not see included)
1. local_j = T(o_j + stretch shift) @ R(q_j^t) @ S(s_j);  G = FK(local)
2. v_i = sum_k w_ik (G_k @ inverse_bind_k) (p_i + e_k(p_i) s_k)          (stretchable LBS)
3. v'_i = u v_i + V_theta(u p_i)                                          (CASA eq. 3)
4. world = R_root v' + t_root

With shared seams, steps 0-4 run once per group of a vertex's identical copies and are gathered.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from ..asset import RiggedAsset
from .displacement import DisplacementField
from .kinematics import KinematicTree, compose_trs, forward_kinematics
from .priors import (
    bone_length_prior,
    find_symmetry_plane,
    smoothness_loss,
    symmetric_joint_pairs,
    symmetry_loss,
)
from .rotations import quat_to_matrix
from .skinning import (
    SkinWeights,
    bone_segments,
    candidate_bones,
    child_offset_shift,
    endpoint_weights,
    linear_blend_skinning,
    seam_groups,
    stretch_vectors,
)

Tensor = torch.Tensor


@dataclass
class Pose:
    """What `ArticulatedModel.forward` returns.

    vertices (..., V, 3) world positions; joints (..., J, 3) world joint positions;
    transforms (..., J, 4, 4) joint-to-model transforms G (before global scale and root).
    """

    vertices: Tensor
    joints: Tensor
    transforms: Tensor


def _rotate_shared(points: Tensor, R: Tensor) -> Tensor:
    """points (V, 3) turned by each rotation R (..., 3, 3) -> (..., V, 3), in one (V, 3) @ (3, 3 x
    rotations) product rather than a batched product over copies of the points."""
    batch = R.shape[:-2]
    cols = R.reshape(-1, 3, 3).permute(2, 0, 1).reshape(3, -1)  # column (n, i) = R[n, i, c]
    return (
        (points @ cols).view(points.shape[0], -1, 3).transpose(0, 1).contiguous().view(batch + points.shape)
    )


class ArticulatedModel(nn.Module):
    """CASA's articulation model for one `RiggedAsset` (Y-up, bind-space template).

    Options: ``num_candidates`` K bones per vertex for the skinning softmax; ``stretch`` enables
    stretchable bones (else plain LBS with bone scales ignored); ``displacement`` adds the MLP
    field (``hidden`` width, ``num_freqs`` positional-encoding octaves); ``dtype``/``device``;
    ``share_seams``: copies of a vertex at one bind position share their learned skinning weights
    (`zooctl.rig.skinning.seam_groups`; off by default here, each copy learning its own; the fit
    turns it on, ``ablation.share_seams``). ``girth``: each bone also scales the template across
    itself, by ``log_bone_girth`` (`girth_offsets`; ``ablation.girth``).
    ``skinning`` (a class attribute) blends the bone transforms: a subclass replaces it (the
    interface is in `zooctl.rig.base`).
    """

    skinning = staticmethod(linear_blend_skinning)

    def __init__(
        self,
        asset: RiggedAsset,
        num_candidates: int = 4,
        stretch: bool = True,
        displacement: bool = True,
        hidden: int = 128,
        num_freqs: int = 0,
        device: torch.device | str = "cpu",
        dtype: torch.dtype = torch.float32,
        share_seams: bool = False,
        girth: bool = False,
    ):
        super().__init__()
        self.asset_name = asset.name
        self.stretch = stretch
        points = asset.vertices.astype(np.float64)
        bind = np.linalg.inv(asset.inverse_bind)
        heads = bind[:, :3, 3]
        dense = asset.skin_weights_dense().astype(np.float64)
        tails = bone_segments(heads, asset.parents, points, dense)
        bones, init = candidate_bones(dense, points, heads, tails, num_candidates)
        rt, rq, rs = asset.rest_trs()
        parents = asset.parents.astype(np.int64)
        # e_parent(c_j): how far along its parent bone each joint's head sits (for the FK shift).
        pj = np.maximum(parents, 0)
        axis = tails[pj] - heads[pj]
        den = np.maximum((axis * axis).sum(-1), 1e-12)
        child_e = np.clip(((heads - heads[pj]) * axis).sum(-1) / den, 0.0, 1.0) * (
            (axis * axis).sum(-1) > 1e-12
        )

        def buf(name: str, arr: np.ndarray, dt: torch.dtype = dtype) -> None:
            self.register_buffer(name, torch.as_tensor(np.ascontiguousarray(arr), dtype=dt))

        buf("points", points)
        # The displacement field reads the bind position alone, which a seam's copies share: it
        # runs once per position (a quarter of the vertices of a flat-shaded animal) and is gathered.
        _, first, inverse = np.unique(points, axis=0, return_index=True, return_inverse=True)
        self.register_buffer("field_index", torch.as_tensor(first), persistent=False)
        self.register_buffer("field_inverse", torch.as_tensor(inverse.reshape(-1)), persistent=False)
        share = np.bincount(inverse.reshape(-1), minlength=len(first)) / max(len(points), 1)
        self.register_buffer("field_share", torch.as_tensor(share, dtype=dtype), persistent=False)
        buf("faces", asset.faces.astype(np.int64), torch.long)
        buf("parents", parents, torch.long)
        buf("inverse_bind", asset.inverse_bind)
        buf("rest_translation", rt)
        buf("rest_rotation", rq)
        buf("rest_scale", rs)
        buf("heads", heads)
        buf("tails", tails)
        buf("child_e", child_e)
        # Joints that skin nothing (armature nodes, helpers) have no bone to stretch.
        self.register_buffer("stretchable", torch.as_tensor(dense.sum(0) > 0))
        pts_t = torch.as_tensor(points, dtype=dtype)
        bones_t = torch.as_tensor(bones)
        head_k = torch.as_tensor(heads, dtype=dtype)[bones_t]  # (V, K, 3)
        tail_k = torch.as_tensor(tails, dtype=dtype)[bones_t]
        e = endpoint_weights(pts_t[:, None, :], head_k, tail_k)
        self.register_buffer("endpoint", e)
        groups = torch.as_tensor(seam_groups(points, bones)) if share_seams else None
        self.skin = SkinWeights(bones_t, torch.as_tensor(init, dtype=dtype), groups=groups)
        self.log_bone_scales = nn.Parameter(torch.zeros(asset.num_joints, dtype=dtype))
        # Where the bone-length prior holds the scales: the template's lengths, or `lengthen`'s.
        self.register_buffer("bone_centre", torch.zeros(asset.num_joints, dtype=dtype))
        self._register_load_state_dict_pre_hook(self._centre_at_template)
        self.log_bone_girth: nn.Parameter | None = None
        if girth:
            nearest = head_k + e[..., None] * (tail_k - head_k)  # (V, K, 3)
            w0 = torch.as_tensor(init, dtype=dtype) * self.stretchable[bones_t]
            # Made from the template, not saved: a fit state from before girths existed still loads.
            radial = w0[..., None] * (pts_t[:, None, :] - nearest)  # (V, K, 3)
            self.register_buffer("girth_radial", radial, persistent=False)
            self.log_bone_girth = nn.Parameter(torch.zeros(asset.num_joints, dtype=dtype))
            self._register_load_state_dict_pre_hook(self._girth_at_one)
        self._register_surface_rows(e)
        self.register_load_state_dict_post_hook(self._surface_rows_after_load)
        self.log_scale = nn.Parameter(torch.zeros((), dtype=dtype))
        self.displacement = (
            DisplacementField(asset.size(), hidden=hidden, num_freqs=num_freqs).to(dtype)
            if displacement
            else None
        )
        self.tree = KinematicTree(parents)
        self.to(device)

    def _register_surface_rows(self, endpoint: Tensor) -> None:
        """The surface is posed once per group of vertices whose every input to skinning is the
        same (bind position, candidate bones, endpoint weights, girth directions and shared
        weights: the copies of a seam) and gathered back: a flat-shaded animal's copies pose to
        one point. ``surface_index`` (U,) a vertex of each group in vertex order, None where no two
        vertices share (seams not shared); ``surface_inverse`` (V,) each vertex's group."""
        V = self.num_vertices
        self.register_buffer("surface_index", None, persistent=False)
        if not self.skin.shared:
            return
        cols = [self.points, self.skin.bones, endpoint, self.skin.groups[:, None]]
        if self.log_bone_girth is not None:
            cols.append(self.girth_radial.flatten(1))
        key = torch.cat([c.double().cpu().reshape(V, -1) for c in cols], 1).numpy()
        _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
        if len(first) == V:
            return
        rank = np.empty(len(first), np.int64)
        rank[np.argsort(first, kind="stable")] = np.arange(len(first))
        index = np.sort(first)
        dev = self.points.device

        def rows(name: str, t: Tensor) -> None:  # made from the template, not saved
            self.register_buffer(
                name, t[torch.as_tensor(index, device=t.device)].contiguous(), persistent=False
            )

        self.register_buffer("surface_index", torch.as_tensor(index, device=dev), persistent=False)
        self.register_buffer(
            "surface_inverse", torch.as_tensor(rank[inverse.reshape(-1)], device=dev), persistent=False
        )
        rows("surface_points", self.points)
        rows("surface_bones", self.skin.bones)
        rows("surface_endpoint", endpoint)
        rows("surface_skin_rows", self.skin.groups)
        rows("surface_field_rows", self.field_inverse)
        if self.log_bone_girth is not None:
            rows("surface_radial", self.girth_radial)

    def _surface_rows_after_load(self, _module, _incompatible_keys) -> None:
        """A loaded state brings its own weight groups: the surface rows follow them."""
        self._register_surface_rows(self.endpoint)

    def _apply(self, fn, *args, **kwargs):  # keep the FK schedule on the module's device
        out = super()._apply(fn, *args, **kwargs)
        self.tree.to(self.points.device)
        return out

    # -- sizes -----------------------------------------------------------------------------
    @property
    def num_joints(self) -> int:
        return int(self.parents.shape[0])

    @property
    def num_vertices(self) -> int:
        return int(self.points.shape[0])

    def bone_scales(self) -> Tensor:
        """(J,) bone-length scales b_k (always positive)."""
        return self.log_bone_scales.exp()

    def global_scale(self) -> Tensor:
        """() the global scale u."""
        return self.log_scale.exp()

    # -- posing ----------------------------------------------------------------------------
    def forward(
        self,
        rotations: Tensor | None = None,
        root_rotation: Tensor | None = None,
        root_translation: Tensor | None = None,
        translations: Tensor | None = None,
        scales: Tensor | None = None,
    ) -> Pose:
        """Pose the model.

        rotations (..., J, 4) local wxyz (default: rest); root_rotation (..., 4) and
        root_translation (..., 3) world transform on top (default: identity); translations and
        scales (..., J, 3) local overrides (default: rest). ``...`` is typically (T,) frames or
        (B, T). Returns a `Pose` with vertices (..., V, 3) and joints (..., J, 3).
        """
        batch = self._batch_shape(rotations, root_rotation, root_translation, translations, scales)
        J = self.num_joints
        rot = self.rest_rotation.expand(*batch, J, 4) if rotations is None else rotations
        trans = self.rest_translation.expand(*batch, J, 3) if translations is None else translations
        scl = self.rest_scale.expand(*batch, J, 3) if scales is None else scales
        s = None
        if self.stretch:
            s = (
                stretch_vectors(self.bone_scales(), self.heads, self.tails) * self.stretchable[:, None]
            )  # (J, 3)
            trans = trans + child_offset_shift(s, self.parents, self.child_e, self.inverse_bind)
        G = forward_kinematics(compose_trs(trans, rot, scl), self.tree)
        mats = G @ self.inverse_bind
        u = self.global_scale()
        R = None if root_rotation is None else quat_to_matrix(root_rotation)  # (..., 3, 3)
        skin, d, dm = self._surface_inputs(s)
        # The field's mean moves the whole mesh (a fit drifts into one: the root translation can
        # take it just as well); the skeleton goes with it, so it stays where the template has it
        # inside the mesh, as in the exported rig (`zooctl.fit.fitted_asset`).
        if self.skinning is linear_blend_skinning:
            # LBS is linear in its matrices: skinning with u R M_k scales and turns the mesh in the
            # same product (no pass over every posed vertex for each); the field is turned alone.
            uR = u * (torch.eye(3, dtype=mats.dtype, device=mats.device) if R is None else R)
            turned = torch.cat((uR[..., None, :, :] @ mats[..., :3, :], mats[..., 3:, :]), -2)
            v = self.skinning(skin[0], turned, *skin[1:])
            joints = G[..., :3, 3] @ uR.transpose(-1, -2)
            if d is not None:
                if R is not None:
                    d, dm = _rotate_shared(d, R), dm @ R.transpose(-1, -2)
                v = v + d
                joints = joints + dm[..., None, :]
        else:
            v = u * self.skinning(skin[0], mats, *skin[1:])
            joints = u * G[..., :3, 3]
            if d is not None:
                v = v + d
                joints = joints + dm
            if R is not None:
                v = v @ R.transpose(-1, -2)
                joints = joints @ R.transpose(-1, -2)
        if root_translation is not None:
            v = v + root_translation[..., None, :]
            joints = joints + root_translation[..., None, :]
        if self.surface_index is not None:
            v = v.index_select(-2, self.surface_inverse)
        return Pose(v, joints, G)

    def _surface_inputs(self, stretch: Tensor | None) -> tuple[tuple, Tensor | None, Tensor | None]:
        """What the skinning reads, a row per posed point ((points, bones, weights, stretch,
        endpoint)), the field's offsets at those rows (or None) and their mean over the vertices:
        a row per vertex, or per group of `_register_surface_rows` where it has them."""
        if self.surface_index is None:
            d = self.displacement_offsets()
            end = self.endpoint if stretch is not None else None
            return (
                (self.rest_points(), self.skin.bones, self.skin(), stretch, end),
                d,
                None if d is None else d.mean(0),
            )
        pts = self.surface_points
        if self.log_bone_girth is not None:
            pts = pts + self._girth_moves(self.surface_bones, self.surface_radial)
        w = self.skin.group_weights().index_select(0, self.surface_skin_rows)
        end = self.surface_endpoint if stretch is not None else None
        f = self._field_at_positions()
        if f is None:
            return (pts, self.surface_bones, w, stretch, end), None, None
        return (
            (pts, self.surface_bones, w, stretch, end),
            f.index_select(0, self.surface_field_rows),
            self.field_share @ f,
        )

    def _batch_shape(
        self, rotations, root_rotation, root_translation, translations, scales
    ) -> tuple[int, ...]:
        for t, tail in (
            (rotations, 2),
            (translations, 2),
            (scales, 2),
            (root_rotation, 1),
            (root_translation, 1),
        ):
            if t is not None:
                return tuple(t.shape[:-tail])
        return ()

    def _centre_at_template(self, state, prefix, *args) -> None:
        """A state saved before `lengthen` existed loads with the template's own lengths."""
        key = prefix + "bone_centre"
        if key not in state:
            state[key] = torch.zeros_like(self.bone_centre)

    @torch.no_grad()
    def lengthen(self, factor: float) -> None:
        """Make the body ``factor`` times longer along the template's longest axis: each
        stretchable bone's length scale starts at ``factor ** cos^2`` of its angle to that axis (a
        spine or a tail in full, an upright leg hardly), and the bone-length prior holds it there."""
        pts = self.points - self.points.mean(0)
        axis = torch.linalg.svd(pts.double(), full_matrices=False)[2][0].to(pts.dtype)
        d = self.tails - self.heads
        n = d.norm(dim=-1)
        cos2 = torch.where(n > 1e-9, (d @ axis / n.clamp_min(1e-9)) ** 2, torch.zeros_like(n))
        self.bone_centre.copy_(cos2 * math.log(factor) * self.stretchable)
        self.log_bone_scales.copy_(self.bone_centre)

    def _girth_at_one(self, state, prefix, *args) -> None:
        """A state saved without girths (before they existed, or with ``girth`` off) loads with
        every girth at 1: the shape it was saved with."""
        key = prefix + "log_bone_girth"
        if key not in state and self.log_bone_girth is not None:
            state[key] = torch.zeros_like(self.log_bone_girth)

    def girth_offsets(self) -> Tensor | None:
        """(V, 3) how far the bones' girths move the bind vertices (before skinning); None without
        girth. A vertex moves across each of its template bones in proportion to its template
        weight on it, so a bone's whole cross-section scales, not only the side a camera sees."""
        if self.log_bone_girth is None:
            return None
        return self._girth_moves(self.skin.bones, self.girth_radial)

    def _girth_moves(self, bones: Tensor, radial: Tensor) -> Tensor:
        """(N, 3) the girths' move of rows with candidate bones (N, K) and directions (N, K, 3)."""
        scale = (self.log_bone_girth.exp() - 1.0).index_select(0, bones.reshape(-1)).view(bones.shape)
        return (scale[..., None] * radial).sum(-2)

    def rest_points(self) -> Tensor:
        """(V, 3) the bind vertices the skinning poses: ``points``, thickened by the girths."""
        g = self.girth_offsets()
        return self.points if g is None else self.points + g

    def displacement_offsets(self) -> Tensor | None:
        """(V, 3) the displacement field's offsets ``V(u p)`` (CASA eq. 3, added after skinning);
        None without a field. Inside `shared_displacement` the field runs once."""
        return self._shared("offsets", lambda: self._field_at_positions().index_select(0, self.field_inverse))

    def _field_at_positions(self) -> Tensor | None:
        """(P, 3) the field at each distinct bind position (``field_index``); None without one."""
        return self._shared(
            "field", lambda: self.displacement(self.global_scale() * self.points[self.field_index])
        )

    def _shared(self, key: str, make) -> Tensor | None:
        """``make()``, made once per `shared_displacement` block; None without a field."""
        if self.displacement is None:
            return None
        cache = getattr(self, "_shared_disp", None)  # a dict inside the block
        if cache is None:
            return make()
        if key not in cache:
            cache[key] = make()
        return cache[key]

    @contextlib.contextmanager
    def shared_displacement(self) -> Iterator[None]:
        """Within this block `displacement_offsets` evaluates the field once and hands every caller
        (posing, the symmetry term, the displacement prior) the same tensor: one loss evaluation
        uses it several times while the parameters stay put. Do not step an optimiser inside."""
        if getattr(self, "_shared_disp", None) is not None:  # nested: the outer block's tensor
            yield
            return
        self._shared_disp: dict[str, Tensor] | None = {}
        try:
            yield
        finally:
            self._shared_disp = None

    def canonical_vertices(self) -> Tensor:
        """(V, 3) the rest-shape template after girth, global scale and displacement: ``u p + V(u p)``."""
        v = self.global_scale() * self.rest_points()
        d = self.displacement_offsets()
        return v if d is None else v + d

    # -- priors ----------------------------------------------------------------------------
    def symmetry_plane(self) -> tuple[Tensor, float]:
        """The template's mirror plane (unit normal (3,), offset), found once and cached."""
        if not hasattr(self, "_plane"):
            n, d, _ = find_symmetry_plane(self.points.detach().cpu().numpy())
            self._plane = (torch.as_tensor(n, dtype=self.points.dtype, device=self.points.device), d)
            tol = 0.02 * float((self.points.max(0).values - self.points.min(0).values).norm())
            pairs = symmetric_joint_pairs(self.heads.cpu().numpy(), n, d, tol)
            self._pairs = torch.as_tensor(pairs, device=self.points.device)
        return self._plane

    def symmetry_loss(self, sample: int | None = 2000) -> Tensor:
        """CASA eq. 7 on `canonical_vertices` (u scales the plane offset too)."""
        n, d = self.symmetry_plane()
        idx = None
        if sample is not None and self.num_vertices > sample:
            gen = torch.Generator().manual_seed(0)
            idx = torch.randperm(self.num_vertices, generator=gen)[:sample].to(self.points.device)
        return symmetry_loss(self.canonical_vertices(), n, d * self.global_scale(), idx)

    def mirrored_joints(self) -> tuple[Tensor, Tensor, Tensor]:
        """The mirror plane of `canonical_vertices` (unit normal (3,), offset () at the current
        global scale) and the (P, 2) joint pairs (left, right) that mirror each other through it."""
        n, d = self.symmetry_plane()
        return n, d * self.global_scale(), self._pairs

    def bone_length_loss(self) -> Tensor:
        """Bone scales (and girths) near 1 and equal between mirrored joints."""
        self.symmetry_plane()
        loss = bone_length_prior(self.log_bone_scales - self.bone_centre, self._pairs)
        if self.log_bone_girth is not None:
            loss = loss + bone_length_prior(self.log_bone_girth, self._pairs)
        return loss

    @staticmethod
    def smoothness_loss(rotations: Tensor) -> Tensor:
        """CASA eq. 6 on (..., T, J, 4) rotations."""
        return smoothness_loss(rotations)
