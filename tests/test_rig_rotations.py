"""Rotation utilities: agreement with the numpy reference, round trips, gradients at the identity."""

import numpy as np
import torch

from zooctl import geometry
from zooctl.rig import rotations as rot

torch.manual_seed(0)


def _rand_quat(n: int) -> torch.Tensor:
    return rot.quat_normalize(torch.randn(n, 4, dtype=torch.float64))


def test_matrix_matches_numpy_and_round_trips():
    q = _rand_quat(200)
    m = rot.quat_to_matrix(q)
    np.testing.assert_allclose(m.numpy(), geometry.quat_to_matrix(q.numpy()), atol=1e-12)
    q2 = rot.matrix_to_quat(m)
    assert torch.allclose(q2 * torch.sign((q2 * q).sum(-1, keepdim=True)), q, atol=1e-10)
    assert (q2[:, 0] >= 0).all()


def test_product_inverse_and_rotate_agree_with_matrices():
    a, b = _rand_quat(50), _rand_quat(50)
    assert torch.allclose(
        rot.quat_to_matrix(rot.quat_mul(a, b)), rot.quat_to_matrix(a) @ rot.quat_to_matrix(b), atol=1e-12
    )
    ident = rot.quat_mul(a, rot.quat_inverse(a))
    assert torch.allclose(ident.abs(), rot.quat_identity(50, dtype=torch.float64), atol=1e-12)
    v = torch.randn(50, 3, dtype=torch.float64)
    assert torch.allclose(rot.quat_rotate(a, v), (rot.quat_to_matrix(a) @ v[..., None])[..., 0], atol=1e-12)
    # broadcasting over a leading batch dimension
    assert rot.quat_rotate(a[:1], v).shape == (50, 3)


def test_6d_and_axis_angle_round_trip():
    q = _rand_quat(100)
    m = rot.quat_to_matrix(q)
    assert torch.allclose(rot.rot6d_to_matrix(rot.matrix_to_rot6d(m)), m, atol=1e-12)
    aa = rot.quat_to_axis_angle(q)
    assert (aa.norm(dim=-1) <= np.pi + 1e-9).all()
    assert rot.quat_angle(rot.axis_angle_to_quat(aa), q).max() < 1e-7
    # the identity is handled without NaN, value and gradient
    zero = torch.zeros(1, 3, dtype=torch.float64, requires_grad=True)
    rot.quat_to_matrix(rot.axis_angle_to_quat(zero)).sum().backward()
    assert torch.isfinite(zero.grad).all()
    assert torch.allclose(
        rot.quat_to_axis_angle(rot.quat_identity(1, dtype=torch.float64)),
        torch.zeros(1, 3, dtype=torch.float64),
    )


def test_gradcheck_conversions():
    q = _rand_quat(4).requires_grad_(True)
    assert torch.autograd.gradcheck(rot.quat_to_matrix, (q,))
    m = rot.quat_to_matrix(_rand_quat(4)).requires_grad_(True)
    assert torch.autograd.gradcheck(rot.matrix_to_quat, (m,))
    d6 = torch.randn(4, 6, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(rot.rot6d_to_matrix, (d6,))
    aa = torch.randn(4, 3, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(rot.axis_angle_to_quat, (aa,))


def _matrix_entrywise(q: torch.Tensor) -> torch.Tensor:
    """The textbook entries, one expression each: the reference for the table form."""
    w, x, y, z = rot.quat_normalize(q).unbind(-1)
    m = torch.stack(
        (
            1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
        ),
        -1,
    )  # fmt: skip
    return m.reshape(q.shape[:-1] + (3, 3))


def test_matrix_table_form_equals_the_entrywise_formula():
    """Any batch shape, unnormalised input, float32 and float64: the same values and gradients."""
    g = torch.Generator().manual_seed(4)
    for shape, dtype in (((4,), torch.float64), ((3, 5, 4), torch.float64), ((2, 7, 4), torch.float32)):
        q = (3 * torch.randn(shape, generator=g, dtype=dtype)).requires_grad_(True)
        got, want = rot.quat_to_matrix(q), _matrix_entrywise(q)
        assert got.shape == shape[:-1] + (3, 3)
        tol = 1e-12 if dtype == torch.float64 else 1e-6
        torch.testing.assert_close(got, want, rtol=tol, atol=tol)
        w = torch.randn(got.shape, generator=g, dtype=dtype)
        torch.testing.assert_close(
            torch.autograd.grad((got * w).sum(), q)[0],
            torch.autograd.grad((want * w).sum(), q)[0],
            rtol=10 * tol,
            atol=10 * tol,
        )
