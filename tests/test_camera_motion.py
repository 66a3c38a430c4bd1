"""The camera's turn read from the background (`zooctl.video.camera_motion`) and the tracker that
carries its prediction by it (``camera.motion = "background"``)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from test_fit_known_camera import _rotation_error_deg

from zooctl.benchdata.appearance import world_backgrounds
from zooctl.fit.camera_init import SilhouetteScorer, initialise_camera, view_rotation
from zooctl.fit.config import CameraConfig
from zooctl.fit.scene import CAMERA_ROTATION
from zooctl.geometry import quat_to_matrix
from zooctl.video.camera_motion import background_motion, kabsch, rotation_ransac

pytestmark = pytest.mark.usefixtures("one_thread")


def _axis_angle(axis, deg: float) -> np.ndarray:
    import cv2

    v = np.asarray(axis, np.float64)
    return cv2.Rodrigues(v / np.linalg.norm(v) * math.radians(deg))[0]


def _panning(frames: int, pan: float, tilt: float) -> np.ndarray:
    """(T, 3, 3) world-to-camera rotations (OpenCV axes, world +y up) of a camera looking 15
    degrees down and turning ``pan`` degrees a frame about the vertical, ``tilt`` about its x axis."""
    look_down = _axis_angle([1, 0, 0], 15.0)
    flip = np.diag([1.0, -1.0, -1.0])  # world +y up, camera y down, looking along world -z
    return np.stack(
        [
            _axis_angle([1, 0, 0], tilt * t) @ look_down @ flip @ _axis_angle([0, 1, 0], pan * t)
            for t in range(frames)
        ]
    )


def _scene(frames: int, pan: float, tilt: float, size: int = 320, seed: int = 0):
    f = 0.5 * size / math.tan(math.radians(20.0))  # the benchmark's field of view, 40 degrees
    K = np.array([f, f, size / 2, size / 2])
    rots = _panning(frames, pan, tilt)
    bg = world_backgrounds(np.random.default_rng(seed), K, rots, (size, size))
    # an "animal" over it: a disc of noise drawn anew every frame, which must not count
    yy, xx = np.mgrid[:size, :size]
    mask = (yy - size * 0.55) ** 2 + (xx - size * 0.5) ** 2 < (size * 0.22) ** 2
    rng = np.random.default_rng(1)
    for f in bg:
        f[mask] = rng.integers(0, 255, (int(mask.sum()), 3))
    return bg, np.repeat(mask[None], frames, 0), K, rots


@pytest.mark.parametrize(("pan", "tilt"), [(1.5, 0.0), (-2.0, 0.3)])
def test_the_turn_of_a_camera_before_a_distant_scene_is_read_from_the_background(pan, tilt):
    frames, masks, K, rots = _scene(16, pan, tilt)
    motion = background_motion(frames, masks, float(K[0]), (K[2], K[3]))
    assert motion.known.all()
    truth = rots @ rots[0].T  # relative to the first frame
    errors = [_rotation_error_deg(motion.rotations[t], truth[t]) for t in range(len(rots))]
    assert max(errors) < 0.5
    assert motion.summary()["net_turn_deg"] == pytest.approx(
        _rotation_error_deg(truth[-1], np.eye(3)), abs=0.5
    )


def test_a_still_background_reads_as_a_camera_at_rest_and_a_plain_one_as_unknown():
    frames, masks, K, _ = _scene(5, 0.0, 0.0)
    still = background_motion(frames, masks, float(K[0]))
    assert still.known.all() and max(_rotation_error_deg(R, np.eye(3)) for R in still.rotations) < 0.05
    plain = np.full_like(frames, 128)
    flat = background_motion(plain, masks, float(K[0]))
    assert not flat.known.any() and np.allclose(flat.rotations, np.eye(3))
    assert flat.summary()["pairs_measured"] == 0


def test_ransac_finds_the_rotation_among_outliers():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(200, 3))
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    R = _axis_angle([0.2, 1.0, 0.1], 7.0)
    b = a @ R.T
    b[:80] = rng.normal(size=(80, 3))  # 40 % of the points move on their own
    b /= np.linalg.norm(b, axis=1, keepdims=True)
    found, inliers = rotation_ransac(a, b, 1e-3, rng)
    assert _rotation_error_deg(found, R) < 0.01 and inliers[80:].all() and not inliers[:80].any()
    assert _rotation_error_deg(kabsch(a[80:], b[80:]), R) < 1e-3


def _orbited(plan: str, pan: float, view_of=None, T: int = 36, size: int = 96, focal: float = 110.0):
    """A procedural ``plan`` still in the world, seen from 30 degrees azimuth, 20 above, by a camera
    orbiting ``pan`` degrees a frame: (asset, camera rotations, the true root rotations, masks).
    ``view_of(t, follow_t, truth_t)``: the root rotation frame t's mask is drawn with instead."""
    from zooctl.procedural import build_animal

    asset = build_animal(plan, name=plan)
    cams = _panning(T, pan, 0.0)
    follow = [CAMERA_ROTATION.T @ C @ cams[0].T @ CAMERA_ROTATION for C in cams]
    truth = [f @ view_rotation(30.0, 20.0) for f in follow]
    scorer = SilhouetteScorer(asset.vertices, asset.faces, np.zeros((T, size, size), bool), size)
    rest = asset.vertices - 0.5 * (asset.vertices.max(0) + asset.vertices.min(0))
    depth = 3.0 * float(np.ptp(rest, axis=0).max())
    views = [view_of(t, follow[t], truth[t]) if view_of else truth[t] for t in range(T)]
    masks = np.stack([scorer.silhouette(rest @ R.T + [0.0, 0.0, -depth], focal) for R in views])
    return asset, cams, truth, masks


@pytest.mark.parametrize("motion", ["given", "none", "reversed"])
def test_the_tracker_follows_a_fast_orbit_with_the_cameras_turn_and_loses_it_without(motion):
    """A body still in the world seen by a camera orbiting at 5 degrees a frame (30 between
    keyframes, twice the tracker's step): carried by the camera's turn, every keyframe is found
    (within the quadruped's own ambiguity, about 25 degrees); tracked without it, or carried the
    wrong way, the track is lost."""
    asset, cams, truth, masks = _orbited("quadruped", 5.0)
    T, focal = len(masks), 110.0
    cfg = CameraConfig(focal=focal, azimuths=12, elevations=[-15.0, 10.0, 35.0])
    given = {"given": cams, "none": None, "reversed": np.stack([cams[0] @ C.T @ cams[0] for C in cams])}[
        motion
    ]
    init = initialise_camera(asset.vertices, asset.faces, masks, cfg, 1.0, camera_motion=given)
    fitted = [quat_to_matrix(q) for q in init.root_rotation]
    worst = max(_rotation_error_deg(fitted[t], truth[t]) for t in range(0, T, 6))
    if motion == "given":
        assert worst < 30.0 and min(init.keyframe_iou) > 0.75
    else:
        assert worst > 45.0


def test_starts_ranked_over_the_whole_clip_recover_a_view_the_first_frames_mislead():
    """A bird still in the world, the camera orbiting at 3 degrees a frame, its first six frames'
    masks of another view (the body seen 90 degrees round, as a first pose unlike the rest pose
    shows the template another outline): the head's starts all follow the wrong view, while
    ``search_over = "both"`` also tracks the starts that match keyframes spread over the clip,
    and keeps one within the tracker's step of the truth from frame 6 on."""
    asset, cams, truth, masks = _orbited(
        "bird", 3.0, lambda t, follow, true: true if t >= 6 else follow @ view_rotation(120.0, 20.0)
    )
    T, focal = len(masks), 110.0
    worst, kept = {}, {}
    for over in ("head", "both"):
        cfg = CameraConfig(focal=focal, azimuths=12, elevations=[-15.0, 10.0, 35.0], search_over=over)
        init = initialise_camera(asset.vertices, asset.faces, masks, cfg, 1.0, camera_motion=cams)
        fitted = [quat_to_matrix(q) for q in init.root_rotation]
        worst[over] = max(_rotation_error_deg(fitted[t], truth[t]) for t in range(6, T, 6))
        kept[over] = float(np.mean(init.keyframe_iou))
    assert worst["head"] > 30.0
    assert worst["both"] < cfg.track_step + 5.0 and kept["both"] > kept["head"]


def test_a_fit_records_the_cameras_turn_and_a_camera_at_rest_changes_nothing(tmp_path):
    """``camera.motion = "background"`` through `fit_video`: fit.json's camera search records the
    turn read; a still background (a camera at rest) leaves the start exactly as without it."""
    from zooctl.benchdata.make import make_video
    from zooctl.fit.config import FitConfig
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.run import fit_video
    from zooctl.procedural import build_animal

    asset = build_animal("quadruped", name="quad")
    base = {"ablation": {"optimise": False}, "camera": {"azimuths": 6, "search_size": 32}}
    on = FitConfig.from_dict(base | {"camera": base["camera"] | {"motion": "background"}})
    off = FitConfig.from_dict(base)
    kw = {"frames": 19, "size": 160, "seed": 1, "appearance": "textured"}
    world = load_fit_video(make_video(asset, tmp_path / "w", background="world", **kw))
    still = load_fit_video(make_video(asset, tmp_path / "s", **kw))
    moved = fit_video(world, asset, on).camera_init["motion"]
    assert moved["used"] and moved["from"] == "background" and moved["pairs_measured"] == 18
    assert moved["span_deg"] >= 15.0
    rest = fit_video(still, asset, on)
    assert rest.camera_init["motion"]["used"] is False and rest.camera_init["motion"]["span_deg"] < 1.0
    plain = fit_video(still, asset, off)
    assert "motion" not in plain.camera_init
    np.testing.assert_array_equal(
        rest.scene.root_rotation.detach().numpy(), plain.scene.root_rotation.detach().numpy()
    )


def test_the_default_reads_the_turn_for_a_named_template_only(tmp_path, store, capsys):
    """``camera.motion`` ``given`` (the default): a template the user named gets ``background``,
    retrieval's candidates none; ``none`` stays none. `zooctl fit --template` records the read
    (a still benchmark video: a camera at rest, not used)."""
    from test_fit_view_trial import TINY, fit_named_tube

    from zooctl.fit.config import FitConfig

    assert CameraConfig().motion == "given"
    assert FitConfig().for_named_template().camera.motion == "background"
    off = FitConfig.from_dict({"camera": {"motion": "none"}})
    assert off.for_named_template().camera.motion == "none"
    rec = fit_named_tube(tmp_path, store, capsys, TINY)
    motion = rec["camera"]["search"]["motion"]
    assert motion["from"] == "background" and motion["used"] is False and motion["span_deg"] < 1.0
    assert rec["config"]["camera"]["motion"] == "background"
