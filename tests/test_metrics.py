"""CASA metrics on shapes with known answers."""

from __future__ import annotations

import numpy as np

from zooctl.fit.metrics import chamfer, scale_line_search, skinning_iou, surface_samples, voxelize
from zooctl.rig.synthetic import uv_sphere


def test_voxel_iou_and_scale_line_search_recover_the_scale():
    v, f = uv_sphere(800)
    gt = surface_samples(v.astype(np.float64) + [0, 0, 6.0], f)
    # The prediction is the same shape twice as far along the camera rays (depth ambiguity).
    pred = gt * 2.0
    s, iou = scale_line_search(pred, gt)
    assert abs(s - 0.5) < 0.02 and iou > 0.9
    # A smaller sphere at the right place scores lower.
    small = surface_samples(0.6 * v.astype(np.float64) + [0, 0, 6.0], f)
    assert scale_line_search(small, gt, np.array([1.0]))[1] < 0.5


def test_voxelize_fills_interiors():
    v, f = uv_sphere(800)
    vox = voxelize(surface_samples(v.astype(np.float64), f, 8000), np.array([-1.5] * 3), 3.0)
    c = vox.shape[0] // 2
    assert vox[c, c, c]  # the centre is inside
    frac = vox.mean()
    assert abs(frac - (4 / 3 * np.pi) / 27) < 0.05  # the sphere's share of the cube


def test_chamfer():
    a = np.stack(np.meshgrid(*[np.arange(5.0)] * 3), -1).reshape(-1, 3)  # points 1 apart
    assert chamfer(a, a) == 0.0
    assert abs(chamfer(a, a + [0.1, 0, 0]) - 0.1) < 1e-9


def test_skinning_matching_is_permutation_invariant():
    rng = np.random.default_rng(0)
    verts = rng.random((400, 3))
    owner = (verts[:, 0] * 4).astype(int)  # 4 slabs = 4 joints
    gt = np.eye(4)[owner]
    perm = np.array([2, 0, 3, 1])
    pred = np.zeros((400, 6))
    pred[:, perm] = gt  # same sets, other joint numbering (and two unused joints)
    assert skinning_iou(verts, gt, verts, pred) == 1.0
    half = gt.copy()
    half[:, [0, 1]] = gt[:, [1, 0]] * 0 + np.eye(4)[np.where(owner < 2, 0, owner)][:, [0, 1]]
    assert skinning_iou(verts, gt, verts, half) < 1.0
