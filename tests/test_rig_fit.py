"""End to end on CPU in seconds: recover a bent joint of a two-bone rig from soft silhouettes."""

import pytest
import torch

from zooctl.render.camera import look_at
from zooctl.render.raster import rasterize
from zooctl.render.soft import SoftSilhouette
from zooctl.rig.model import ArticulatedModel
from zooctl.rig.rotations import axis_angle_to_quat
from zooctl.rig.synthetic import tube_asset

pytestmark = pytest.mark.usefixtures("one_thread")  # see conftest


def test_recovers_a_bent_joint_from_masks_over_frames():
    asset = tube_asset(bones=2, rings_per_bone=6, segments=12, radius=0.15)
    model = ArticulatedModel(asset, displacement=False)
    cam = look_at([1.0, 0.0, 4.0], [1.0, 0.0, 0.0], 48, 48, fov_y_degrees=45)
    faces = model.faces
    true = torch.tensor([0.4, 0.7, 1.0])  # bend of joint 1 about Z in three frames

    def pose(angles):
        aa = torch.zeros(len(angles), 2, 3)
        aa[:, 1, 2] = angles
        return model(axis_angle_to_quat(aa)).vertices

    with torch.no_grad():
        target = rasterize(pose(true), faces, cam).mask.float()
    angles = torch.full((3,), 0.1, requires_grad=True)
    opt = torch.optim.Adam([angles], lr=0.05)
    coarse, fine = SoftSilhouette(48, sigma=1.0), SoftSilhouette(48, sigma=0.1)
    for i in range(80):
        opt.zero_grad()
        sil = (coarse if i < 50 else fine)(pose(angles), faces, cam)
        ((sil - target) ** 2).mean().backward()
        opt.step()
    assert (angles.detach() - true).abs().max() < 0.05
