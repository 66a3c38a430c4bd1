"""Camera convention: projection, look_at, and the USD round trip checked against pxr's Gf.Camera."""

import numpy as np
import pytest
import torch

from zooctl.errors import InputError
from zooctl.render.camera import Camera, from_usd, look_at, to_usd


def test_look_at_projects_target_to_centre_and_up_to_image_top():
    cam = look_at([[3.0, 1.0, 4.0]], [0.0, 0.5, 0.0], 60, 80, fov_y_degrees=50)
    xy, z = cam.project(torch.tensor([[[0.0, 0.5, 0.0], [0.0, 1.5, 0.0]]]))
    assert torch.allclose(xy[0, 0], torch.tensor([40.0, 30.0]), atol=1e-4)
    assert z[0, 0] > 0 and xy[0, 1, 1] < xy[0, 0, 1]  # world up is image up (smaller row)


def test_usd_round_trip_and_agreement_with_gf_camera():
    pxr = pytest.importorskip("pxr", reason="usd-core is not installed")
    from pxr import Gf

    cam = look_at([[2.0, 1.5, -3.0]], [0.2, 0.1, 0.3], 90, 160, fov_y_degrees=35, dtype=torch.float64)
    cam.intrinsics[0, 2:] += torch.tensor([7.0, -4.0], dtype=torch.float64)  # off-centre principal point
    usd = to_usd(cam)
    back = from_usd(
        **{k: usd[k] for k in usd if k != "camera_to_world"},
        camera_to_world=usd["camera_to_world"],
        height=90,
        width=160,
        dtype=torch.float64,
    )
    for a, b in (
        (cam.intrinsics, back.intrinsics),
        (cam.rotation, back.rotation),
        (cam.translation, back.translation),
    ):
        assert torch.allclose(a, b, atol=1e-9)
    gf = Gf.Camera(
        Gf.Matrix4d(usd["camera_to_world"].T.tolist()), Gf.Camera.Perspective,
        usd["horizontal_aperture"], usd["vertical_aperture"],
        usd["horizontal_aperture_offset"], usd["vertical_aperture_offset"], usd["focal_length"],
    )  # fmt: skip
    fr = gf.frustum
    view, proj = fr.ComputeViewMatrix(), fr.ComputeProjectionMatrix()
    pts = np.random.default_rng(0).normal(size=(20, 3)) * 0.5 + [0.2, 0.1, 0.3]
    ours, _ = cam.project(torch.as_tensor(pts)[None])
    for p, (u, v) in zip(pts, ours[0].numpy(), strict=True):
        ndc = proj.Transform(view.Transform(Gf.Vec3d(*p)))
        assert abs((ndc[0] + 1) / 2 * 160 - u) < 1e-6 and abs((1 - ndc[1]) / 2 * 90 - v) < 1e-6
    assert pxr is not None


def test_bad_cameras_raise_input_errors():
    with pytest.raises(InputError):
        Camera(torch.zeros(1, 3), torch.eye(3)[None], torch.zeros(1, 3), 10, 10)
    with pytest.raises(InputError):
        look_at([0.0, 5.0, 0.0], [0.0, 0.0, 0.0], 10, 10)  # looking straight down the up axis
    with pytest.raises(InputError):
        from_usd(-1.0, 20.0, 10.0, np.eye(4), 10, 20)
