"""The CPU projection kernels (`Camera.project`, `Camera.to_camera`) against Camera's PyTorch
expressions: values and the gradients of points, rotation, translation and intrinsics; the face
window kernel against `face_windows`."""

from __future__ import annotations

import pytest
import torch

from zooctl.render import _kernels
from zooctl.render.camera import Camera

pytestmark = pytest.mark.skipif(not _kernels.available(), reason="no C++ compiler: the kernels are not built")


def _inputs(dtype, B=3, N=41, shared=False, seed=0, fixed_pose=False):
    g = torch.Generator().manual_seed(seed)
    pts = (
        torch.randn(B, N, 3, generator=g, dtype=torch.float64)
        + torch.tensor([0.0, 0.0, 4.0], dtype=torch.float64)
    ).to(dtype)
    pts[0, 3, 2] = -2.0  # behind the camera
    pts[1, 5] = torch.tensor([0.3, -0.2, 1e-14], dtype=dtype)  # on the camera plane: the depth clamp
    C = 1 if shared else B
    q, _ = torch.linalg.qr(torch.randn(C, 3, 3, generator=g, dtype=torch.float64))
    R = q.to(dtype)
    t = (0.1 * torch.randn(C, 3, generator=g, dtype=torch.float64)).to(dtype)
    K = torch.tensor([[120.0, 110.0, 32.0, 24.0]], dtype=torch.float64).repeat(C, 1).to(dtype)
    K = K + torch.rand(C, 4, generator=g, dtype=torch.float64).to(dtype)
    pose = not fixed_pose  # a fit's camera: rotation and translation constant
    return [x.requires_grad_(grad) for x, grad in zip((pts, R, t, K), (True, pose, pose, True), strict=True)]


def _run(fn, dtype, shared, seed, fixed_pose=False):
    leaves = _inputs(dtype, shared=shared, seed=seed, fixed_pose=fixed_pose)
    pts, R, t, K = leaves
    cam = Camera(K, R, t, 48, 64)
    outs = fn(cam, pts)
    g = torch.Generator().manual_seed(seed + 100)
    loss = sum((o * torch.randn(o.shape, generator=g, dtype=torch.float64).to(dtype)).sum() for o in outs)
    loss.backward()
    return [o.detach() for o in outs], [x.grad for x in leaves]


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("shared", [False, True])
@pytest.mark.parametrize("which", ["project", "to_camera", "project, fixed pose"])
def test_projection_kernel_matches_pytorch(dtype, shared, which):
    def fn(cam, pts):
        return (cam.to_camera(pts),) if which == "to_camera" else cam.project(pts)

    fixed = which.endswith("fixed pose")
    outs, grads = _run(fn, dtype, shared, seed=1, fixed_pose=fixed)
    with _kernels.disabled():
        ref_outs, ref_grads = _run(fn, dtype, shared, seed=1, fixed_pose=fixed)
    rtol = 1e-5 if dtype == torch.float32 else 1e-12
    for a, b in zip(outs, ref_outs, strict=True):
        torch.testing.assert_close(a, b, rtol=rtol, atol=rtol * b.abs().max().item())
    # A camera's pose gradients are sums over its points of terms as large as a point's gradient
    # (translation) or that times a coordinate (rotation), which cancel: in float32 two summation
    # orders can differ by about eps x terms x the largest term, more than rtol x the sum itself.
    pts = _inputs(dtype, shared=shared, seed=1)[0]
    bound = pts.numel() / 3 * ref_grads[0].abs().max().item()
    bound = {"translation": bound, "rotation": bound * pts.abs().max().item()}
    for name, a, b in zip(("points", "rotation", "translation", "intrinsics"), grads, ref_grads, strict=True):
        if b is None:  # to_camera does not use the intrinsics; a fixed pose has no gradient
            assert a is None, name
            continue
        atol = rtol * b.abs().max().item()
        if name in bound:
            atol = max(atol, 4 * torch.finfo(dtype).eps * bound[name])
        torch.testing.assert_close(a, b, rtol=rtol, atol=atol, msg=name)


def test_projection_kernel_is_used_and_differs_from_a_wrong_camera():
    """The kernel path is taken for CPU float tensors (a changed translation changes its output)."""
    pts, R, t, K = _inputs(torch.float32)
    cam = Camera(K, R, t, 48, 64)
    assert cam._kernel_tensors(pts, "project_forward") is not None
    xy, _ = cam.project(pts)
    moved = Camera(K, R, t + 0.5, 48, 64).project(pts)[0]
    assert (xy - moved).abs().max() > 1.0


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("margin", [0.0, 1.52])
def test_face_windows_kernel_matches_pytorch(dtype, margin):
    """Windows of faces inside, across and beyond the image borders, tiny and invalid ones, exactly
    the PyTorch expression's."""
    from zooctl.render.windows import ScreenFaces, face_windows, face_windows_int32

    g = torch.Generator().manual_seed(2)
    H, W, B, F = 30, 41, 2, 600
    tri = (torch.rand(B * F, 3, 2, generator=g, dtype=torch.float64) * 70 - 15).to(dtype)
    tri[:50] = tri[:50, :1] + 0.01 * tri[:50]  # tiny faces: windows of a pixel or none
    tri[50:60] += 1000.0  # far beyond the image: empty
    valid = torch.rand(B * F, generator=g) > 0.1
    tri[~valid] = float("nan")  # invalid faces may hold NaN corners
    sf = ScreenFaces(tri, torch.ones(B * F, 3, dtype=dtype), valid, B, F)
    ref = face_windows(sf, H, W, margin).to(torch.int32)
    got = face_windows_int32(sf, H, W, margin)
    assert got.dtype == torch.int32 and got.is_contiguous()
    assert torch.equal(got, ref)
    assert (ref[:, 2] >= ref[:, 0]).sum() > 100 and (ref[valid, 2] < ref[valid, 0]).any()
