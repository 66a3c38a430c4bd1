"""`FitScene`: everything a fit optimises, as one ``nn.Module``.

- the articulated template: the articulation model registered as ``articulation`` (default
  ``casa``: `zooctl.rig.model.ArticulatedModel`; interface in `zooctl.rig.base`): global scale u,
  bone length scales, skinning logits, displacement MLP (per animal);
- per-frame motion: local joint quaternions (T, J, 4), root rotation (T, 4) and root
  translation (T, 3) in world space;
- a fixed camera at the world origin looking down world -Z (OpenCV frame: ``R = diag(1, -1, -1)``,
  ``t = 0``), with a learnable focal length. The root motion absorbs any camera motion of the
  video, so the exported USD camera is static at ``/World/Camera``.

World is zooctl's (Y up, right-handed); the fit image is (h, w) pixels with the principal point at
its centre.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
from torch import nn

from ..asset import RiggedAsset
from ..render.camera import Camera
from ..rig.base import get_articulation_model
from ..rig.model import Pose

Tensor = torch.Tensor
CAMERA_ROTATION = np.diag([1.0, -1.0, -1.0])  # world -> OpenCV camera frame (looks down world -Z)


class FitScene(nn.Module):
    """An asset fitted to a T-frame video seen in (h, w) images.

    ``articulation`` names a registered articulation model; ``stretch``/``displacement`` switch
    the CASA articulation parts (ablations); ``hidden`` is the displacement MLP width.
    """

    def __init__(
        self,
        asset: RiggedAsset,
        num_frames: int,
        height: int,
        width: int,
        focal: float,
        stretch: bool = True,
        displacement: bool = True,
        hidden: int = 64,
        device: str = "cpu",
        principal: tuple[float, float] | None = None,
        articulation: str = "casa",
        **options: Any,
    ):
        super().__init__()
        self.height, self.width = int(height), int(width)
        # Principal point in fit pixels: the image centre, or where it falls in a crop.
        self.principal = principal if principal is not None else (width / 2.0, height / 2.0)
        self.model = get_articulation_model(
            articulation,
            asset,
            device=device,
            stretch=stretch,
            displacement=displacement,
            hidden=hidden,
            **options,
        )
        T, J = int(num_frames), self.model.num_joints
        rest_q = self.model.rest_rotation.detach().clone()
        self.rotations = nn.Parameter(rest_q[None].repeat(T, 1, 1))  # (T, J, 4)
        self.root_rotation = nn.Parameter(torch.tensor([1.0, 0, 0, 0], device=device).repeat(T, 1))  # (T, 4)
        self.root_translation = nn.Parameter(torch.zeros(T, 3, device=device))  # (T, 3)
        self.log_focal = nn.Parameter(torch.tensor(math.log(focal), device=device))
        self.register_buffer("init_logits", self.model.skin.logits.detach().clone())
        self._register_load_state_dict_pre_hook(self._shared_init_logits)
        self.size = float(asset.size())
        self.num_joints = J
        self.clip_stats = None  # `zooctl.fit.pose_prior.ClipPoseStats` for the clips pose prior
        self.joint_limits = None  # `zooctl.fit.pose_prior.JointLimits` for ``weights.joint_limits``
        self.sequence_prior = None  # the motion pose prior (`zooctl.fit.pose_prior.motion_sequence_prior`)

    def _shared_init_logits(self, state, prefix, *args) -> None:
        """A state saved without shared seams (a row of initial logits per vertex) loads into a
        scene whose model shares them: each group's mean."""
        key, skin = prefix + "init_logits", self.model.skin
        if key in state and hasattr(skin, "as_groups"):  # a plugin's skinning may not group
            state[key] = skin.as_groups(state[key])

    @property
    def num_frames(self) -> int:
        return int(self.rotations.shape[0])

    @property
    def faces(self) -> Tensor:
        return self.model.faces

    def focal(self) -> Tensor:
        return self.log_focal.exp()

    def camera(self, batch: int = 1) -> Camera:
        """The fit camera (fit-image pixels), repeated ``batch`` times."""
        f = self.focal()
        k = torch.stack((f, f, f.new_tensor(self.principal[0]), f.new_tensor(self.principal[1])))
        R = torch.as_tensor(CAMERA_ROTATION, dtype=f.dtype, device=f.device)
        cam = Camera(k[None], R[None], f.new_zeros(1, 3), self.height, self.width)
        return cam.expand(batch)

    def pose(self, frames: Tensor | slice | None = None) -> Pose:
        """Posed world vertices (B, V, 3) and joints (B, J, 3) of the chosen frames (all by default)."""
        sel = slice(None) if frames is None else frames
        return self.model(self.rotations[sel], self.root_rotation[sel], self.root_translation[sel])

    def pose_with_rest(self, frames: Tensor) -> tuple[Pose, Tensor]:
        """`pose` of ``frames`` (B,), and (V, 3) the rest shape as it is now (``model()``'s
        vertices, no gradient), posed in the same call as one more pose (the rest rotations, no
        root transform): one pass through the model a step instead of two."""
        rest_q = self.model.rest_rotation.detach()
        root_q = self.root_rotation.new_tensor([1.0, 0.0, 0.0, 0.0])
        p = self.model(
            torch.cat((self.rotations.index_select(0, frames), rest_q[None])),
            torch.cat((self.root_rotation.index_select(0, frames), root_q[None])),
            torch.cat((self.root_translation.index_select(0, frames), self.root_translation.new_zeros(1, 3))),
        )
        return Pose(p.vertices[:-1], p.joints[:-1], p.transforms[:-1]), p.vertices[-1].detach()

    def pose_rigid(self, frames: Tensor) -> Tensor:
        """(B, V, 3) world vertices of the *rest* pose under each frame's root transform and the
        global scale: stage 1's cheap pose (no skinning; exact while joints are at rest)."""
        if not hasattr(self, "_rest0") or self._rest0.device != self.rotations.device:
            with torch.no_grad():
                self._rest0 = self.model().vertices / self.model.global_scale()
        from ..rig.rotations import quat_to_matrix

        R = quat_to_matrix(self.root_rotation[frames])  # (B, 3, 3)
        v = self.model.global_scale() * self._rest0
        return v @ R.transpose(-1, -2) + self.root_translation[frames][:, None, :]

    def per_frame_parameters(self) -> list[nn.Parameter]:
        return [self.rotations, self.root_rotation, self.root_translation]

    def shape_parameters(self) -> list[nn.Parameter]:
        ps = [self.model.log_scale, self.model.log_bone_scales]
        if getattr(self.model, "log_bone_girth", None) is not None:
            ps.append(self.model.log_bone_girth)
        if self.model.displacement is not None:
            ps += list(self.model.displacement.parameters())
        return ps

    def rest_vertices(self) -> Tensor:
        """(V, 3) the template at its rest pose, before the global scale and the root transform."""
        with torch.no_grad():
            return self.model().vertices / self.model.global_scale()
