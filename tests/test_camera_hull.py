"""The camera search's box alignment reads only the template's convex hull
(`zooctl.fit.camera_init.hull_points`): the same translations and boxes as from every vertex."""

from __future__ import annotations

import numpy as np

from zooctl.fit.camera_init import (
    SilhouetteScorer,
    _projected_box,
    align_translation,
    hull_points,
    view_rotation,
)
from zooctl.fit.scene import CAMERA_ROTATION
from zooctl.geometry import quat_to_matrix


def test_hull_points_give_the_same_projected_box():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(500, 3)) * [0.6, 0.2, 0.1]
    hull = hull_points(pts)
    assert len(hull) < len(pts)
    box = np.array([20.0, 30.0, 70.0, 50.0])
    for _ in range(10):
        R = view_rotation(*rng.uniform(-180, 180, 3))
        t = align_translation(pts @ R.T, box, 80.0, 48.0, 40.0)
        np.testing.assert_allclose(t, align_translation(hull @ R.T, box, 80.0, 48.0, 40.0), atol=1e-9)
        cam = (pts @ R.T + t) @ CAMERA_ROTATION.T
        hcam = (hull @ R.T + t) @ CAMERA_ROTATION.T
        for a, b in zip(
            _projected_box(cam, 80.0, 48.0, 40.0), _projected_box(hcam, 80.0, 48.0, 40.0), strict=True
        ):
            np.testing.assert_allclose(a, b, atol=1e-9)
    flat = np.c_[rng.normal(size=(50, 2)), np.zeros(50)]  # no volume: every point is kept
    assert len(hull_points(flat)) == 50
    assert len(hull_points(pts[:4])) == 4


def test_the_scorer_places_a_mesh_by_its_hull():
    import trimesh

    # A long body with a head: the head's far side and the body's inner corners are off the hull.
    body = trimesh.creation.box(extents=(1.0, 0.3, 0.3))
    head = trimesh.creation.icosphere(subdivisions=2, radius=0.25)
    head.apply_translation((0.55, 0.2, 0.0))
    mesh = trimesh.util.concatenate([body, head])
    masks = np.zeros((1, 40, 60), bool)
    masks[0, 12:28, 8:52] = True
    sc = SilhouetteScorer(np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces), masks, 32)
    assert len(sc.hull) < len(sc.rest)
    for az in (0.0, 40.0, 90.0):
        R = view_rotation(az, 15.0, 0.0)
        full = align_translation(sc.rest @ R.T, sc.boxes[0], 50.0 * sc.scale, sc.cx, sc.cy)
        np.testing.assert_allclose(sc.place(R, 0, 50.0), full, atol=1e-9)


def test_a_long_body_seen_end_on_is_placed_to_fill_its_box():
    """A thin body ten times longer than it is wide, turned every way: its box alignment matches
    the mask's box within 1 % and keeps every point in front of the camera. Seen nearly end on,
    near the camera, its near end's projection grows faster than the fixed-point passes assume;
    there they used to throw the body hundreds of lengths away (the bisection takes over)."""
    rng = np.random.default_rng(0)
    rod = rng.normal(size=(400, 3)) * [1.0, 0.05, 0.05]
    box = np.array([28.0, 23.0, 40.0, 44.0])  # a small mask, as a snake's at the search's 64 px
    worst = 0.0
    for _ in range(300):
        R = view_rotation(*rng.uniform(-180, 180, 3))
        t = align_translation(rod @ R.T, box, 88.0, 32.0, 32.0)
        cam = (rod @ R.T + t) @ CAMERA_ROTATION.T
        assert cam[:, 2].min() > 0
        lo, hi = _projected_box(cam, 88.0, 32.0, 32.0)
        size = np.sqrt(np.prod(hi - lo) / np.prod(box[2:] - box[:2]))
        worst = max(worst, abs(np.log(size)))
        np.testing.assert_allclose(0.5 * (lo + hi), 0.5 * (box[:2] + box[2:]), atol=1.5)
    assert worst < 0.01


def _project(points: np.ndarray) -> np.ndarray:
    cam = points @ CAMERA_ROTATION.T  # the scene's camera looks down -Z
    return cam[:, :2] / cam[:, 2:]


def test_held_and_trend_distances_keep_each_frame_in_its_place_on_the_image():
    """`camera.depth`: each frame's body centre stays on its ray (its projection unchanged) and its
    log distance becomes the frames' median (held) or their least-squares line (trend); a frame
    without a mask does not count; with fewer than two frames nothing moves."""
    from zooctl.fit.camera_init import _depth_held
    from zooctl.geometry import matrix_to_quat

    rng = np.random.default_rng(3)
    T = 9
    rot_q = np.stack([matrix_to_quat(view_rotation(*rng.uniform(-180, 180, 3))) for _ in range(T)])
    R = np.stack([quat_to_matrix(q) for q in rot_q])
    centre = np.array([0.3, -0.2, 0.5])
    dist = np.exp(np.linspace(1.0, 1.6, T) + rng.normal(0, 0.3, T))  # a trend and jumps about it
    rays = np.c_[rng.uniform(-0.2, 0.2, (T, 2)), -np.ones(T)]
    body = rays * dist[:, None]
    trans = body - R @ centre
    present = np.array([0, 1, 2, 4, 5, 6, 7, 8])  # frame 3 has no mask
    for depth in ("held", "trend"):
        out = _depth_held(trans, rot_q, centre, present, depth)
        moved = out + R @ centre
        np.testing.assert_allclose(_project(moved), _project(body), atol=1e-9)
        log_d = np.log(-moved[:, 2])
        if depth == "held":
            np.testing.assert_allclose(log_d, np.median(np.log(dist[present])), atol=1e-9)
        else:
            slope, at0 = np.polyfit(present, np.log(dist[present]), 1)
            np.testing.assert_allclose(log_d, slope * np.arange(T) + at0, atol=1e-9)
            assert slope > 0
        assert np.std(log_d) < np.std(np.log(dist))
    np.testing.assert_allclose(_depth_held(trans, rot_q, centre, np.array([4]), "held"), trans)
