"""Hard z-buffer: depth and face ids against ray casting, flow against analytic rigid motion."""

import numpy as np
import torch

from zooctl.render.camera import look_at
from zooctl.render.raster import RasterFlow, interpolate, rasterize
from zooctl.rig.rotations import axis_angle_to_quat, quat_to_matrix


def _plane(n=6, size=1.0):
    """A tilted n x n grid of quads (2 n^2 triangles) through the origin."""
    g = np.linspace(-size, size, n + 1)
    xx, yy = np.meshgrid(g, g)
    v = np.stack((xx.ravel(), yy.ravel(), 0.3 * xx.ravel() - 0.2 * yy.ravel()), -1)
    f = []
    for i in range(n):
        for j in range(n):
            a = i * (n + 1) + j
            f += [(a, a + 1, a + n + 1), (a + 1, a + n + 2, a + n + 1)]
    return torch.tensor(v, dtype=torch.float64), torch.tensor(f)


def test_depth_and_face_ids_match_ray_casting():
    torch.manual_seed(0)
    verts = torch.randn(12, 3, dtype=torch.float64) * 0.6
    faces = torch.randint(0, 12, (10, 3))
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])]
    cam = look_at([0.0, 0.0, 3.0], [0.0, 0.0, 0.0], 24, 32, dtype=torch.float64)
    fr = rasterize(verts[None], faces, cam)
    K, R, t = cam.intrinsics[0].numpy(), cam.rotation[0].numpy(), cam.translation[0].numpy()
    pc = verts.numpy() @ R.T + t
    for i in range(24):
        for j in range(32):
            d = np.array([(j + 0.5 - K[2]) / K[0], (i + 0.5 - K[3]) / K[1], 1.0])  # ray with z = 1
            best, best_f = np.inf, -1
            for fi, (a, b, c) in enumerate(faces.numpy()):
                A = np.stack((pc[a] - pc[c], pc[b] - pc[c], -d), 1)
                if abs(np.linalg.det(A)) < 1e-12:
                    continue
                u, v, z = np.linalg.solve(A, -pc[c])
                if u >= 0 and v >= 0 and u + v <= 1 and 0 < z < best:
                    best, best_f = z, fi
            assert int(fr.face_ids[0, i, j]) == best_f or abs(best - float(fr.depth[0, i, j])) < 1e-9
            if best_f >= 0:
                assert abs(float(fr.depth[0, i, j]) - best) < 1e-9
            else:
                assert not fr.mask[0, i, j]


def test_flow_of_a_rigid_motion_matches_the_analytic_flow():
    verts, faces = _plane()
    cam = look_at([0.5, 0.4, 3.0], [0.0, 0.0, 0.0], 64, 64, dtype=torch.float64)
    R = quat_to_matrix(axis_angle_to_quat(torch.tensor([0.05, -0.08, 0.1], dtype=torch.float64)))
    T = torch.tensor([0.06, -0.04, 0.1], dtype=torch.float64)
    moved = verts @ R.T + T
    out = RasterFlow()(verts[None], faces, cam, moved[None])
    m = out["mask"][0]
    assert m.sum() > 1000
    # Analytic: the ray through each pixel hits the (planar) surface at a known point X; it moves to R X + T.
    K, Rc, tc = cam.intrinsics[0], cam.rotation[0], cam.translation[0]
    ii, jj = torch.meshgrid(
        torch.arange(64, dtype=torch.float64) + 0.5,
        torch.arange(64, dtype=torch.float64) + 0.5,
        indexing="ij",
    )
    ray_c = torch.stack(((jj - K[2]) / K[0], (ii - K[3]) / K[1], torch.ones_like(ii)), -1)
    origin = -Rc.T @ tc
    ray_w = ray_c @ Rc  # camera -> world direction
    n = torch.tensor([0.3, -0.2, -1.0], dtype=torch.float64)  # plane z = 0.3 x - 0.2 y
    s = -(origin @ n) / (ray_w @ n)
    X = origin + s[..., None] * ray_w
    X1 = (X @ R.T + T) @ Rc.T + tc
    uv1 = X1[..., :2] / X1[..., 2:] * K[:2] + K[2:]
    expected = uv1 - torch.stack((jj, ii), -1)
    err = (out["flow"][0] - expected).norm(dim=-1)[m]
    assert err.median() < 0.1 and err.max() < 1e-6
    assert expected[m].norm(dim=-1).median() > 2.0  # the motion is not trivial


def test_interpolation_and_gradients_are_finite():
    verts, faces = _plane(3)
    cam = look_at([0.0, 0.0, 3.0], [0.0, 0.0, 0.0], 16, 16, dtype=torch.float64)
    v = verts[None].clone().requires_grad_(True)
    fr = rasterize(v, faces, cam)
    pos = interpolate(v, faces, fr)
    assert torch.allclose(pos[..., 2][fr.mask], (0.3 * pos[..., 0] - 0.2 * pos[..., 1])[fr.mask], atol=1e-9)
    (fr.depth.sum() + pos.sum()).backward()
    assert torch.isfinite(v.grad).all() and v.grad.abs().sum() > 0
    assert torch.autograd.gradcheck(lambda x: rasterize(x, faces, cam).depth, (v,))
