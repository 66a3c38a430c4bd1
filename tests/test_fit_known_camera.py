"""Known camera rotations (`zooctl fit --cameras`, `bench run --known-camera`): the viewpoint
search then finds one world orientation of the animal, and the camera's motion carries it to
every frame instead of a silhouette tracker."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import run_inprocess

from zooctl.errors import InputError, UsageError
from zooctl.fit.camera_init import camera_follow, initialise_camera, view_rotation
from zooctl.fit.config import CameraConfig
from zooctl.fit.inputs import FitVideo, load_camera_rotations, load_fit_video
from zooctl.fit.scene import CAMERA_ROTATION
from zooctl.geometry import quat_to_matrix

pytestmark = pytest.mark.usefixtures("one_thread")


def _random_rotations(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.stack([view_rotation(*rng.uniform(-180, 180, 3)) for _ in range(n)])


def test_camera_follow_keeps_the_world_orientation():
    C = _random_rotations(6, 0)
    W = view_rotation(40.0, -20.0, 10.0)  # the animal's (template -> world) orientation
    first = 2
    F = camera_follow(C, first)
    R_first = CAMERA_ROTATION.T @ C[first] @ W  # the fit's root rotation that frame ``first`` sees
    np.testing.assert_allclose(F[first], np.eye(3), atol=1e-12)
    for t in range(len(C)):
        # What the camera sees at t: the fixed camera (CAMERA_ROTATION) times the root rotation.
        np.testing.assert_allclose(CAMERA_ROTATION @ F[t] @ R_first, C[t] @ W, atol=1e-12)


def _rotation_error_deg(A: np.ndarray, B: np.ndarray) -> float:
    return math.degrees(math.acos(np.clip((np.trace(A.T @ B) - 1) / 2, -1.0, 1.0)))


def _procrustes_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    A, B = a - a.mean(0), b - b.mean(0)
    U, _, Vt = np.linalg.svd(A.T @ B)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return (U @ D @ Vt).T


@pytest.fixture(scope="module")
def orbit_video(tmp_path_factory):
    """A procedural quadruped filmed by `bench make`'s orbiting camera (about 60 degrees)."""
    from zooctl.benchdata.make import make_video
    from zooctl.procedural import build_animal

    root = tmp_path_factory.mktemp("known")
    asset = build_animal("quadruped", name="quadruped")
    folder = make_video(asset, root / "videos", frames=36, size=96, seed=5)
    return asset, folder


def test_known_cameras_follow_the_orbit(orbit_video):
    """Every frame's initial root rotation stays near the truth over the orbit."""
    asset, folder = orbit_video
    video = load_fit_video(folder)
    gt = video.gt
    cfg = CameraConfig(focal=float(video.intrinsics[0]), azimuths=12, elevations=[-15.0, 10.0, 35.0])
    init = initialise_camera(
        asset.vertices, asset.faces, video.masks, cfg, 1.0, camera_rotations=gt["cam_rotation"]
    )
    errs = []
    for t in range(0, video.num_frames, 5):
        gv = gt["vertices"][t] @ gt["cam_rotation"][t].T + gt["cam_translation"][t]
        truth = _procrustes_rotation(asset.vertices, gv)  # rest -> camera frame (posed: approximate)
        fitted = CAMERA_ROTATION @ quat_to_matrix(init.root_rotation[t])
        errs.append(_rotation_error_deg(truth, fitted))
    assert max(errs) < 35.0, errs
    # The camera's motion is carried exactly: the relative rotation of any two frames is the
    # camera's own.
    R = np.stack([CAMERA_ROTATION @ quat_to_matrix(q) for q in init.root_rotation])
    C = gt["cam_rotation"]
    for t in (10, 35):
        np.testing.assert_allclose(R[t] @ R[0].T, C[t] @ C[0].T, atol=1e-5)


def _video(T: int = 4) -> FitVideo:
    return FitVideo("v", np.zeros((T, 8, 8, 3), np.uint8), np.ones((T, 8, 8), bool))


def test_camera_files_are_read_and_checked(tmp_path):
    rots = _random_rotations(6, 1)
    np.savez(tmp_path / "cams.npz", rotations=rots)
    (tmp_path / "cams.json").write_text(json.dumps({"rotations": rots.tolist()}))
    np.testing.assert_allclose(load_camera_rotations(str(tmp_path / "cams.npz"), _video()), rots[:4])
    np.testing.assert_allclose(load_camera_rotations(str(tmp_path / "cams.json"), _video()), rots[:4])
    with pytest.raises(InputError, match=r"of shape \(6, 3, 3\) for a video of 8 frames"):
        load_camera_rotations(str(tmp_path / "cams.npz"), _video(8))
    bad = rots.copy()
    bad[1] *= 2.0
    np.savez(tmp_path / "bad.npz", rotations=bad)
    with pytest.raises(InputError, match="not all rotation matrices"):
        load_camera_rotations(str(tmp_path / "bad.npz"), _video())
    mirror = rots.copy()
    mirror[0, :, 0] *= -1  # orthonormal, determinant -1
    np.savez(tmp_path / "mirror.npz", rotations=mirror)
    with pytest.raises(InputError, match="not all rotation matrices"):
        load_camera_rotations(str(tmp_path / "mirror.npz"), _video())
    np.savez(tmp_path / "other.npz", R=rots)
    with pytest.raises(InputError, match="unreadable"):
        load_camera_rotations(str(tmp_path / "other.npz"), _video())
    with pytest.raises(InputError, match="does not exist"):
        load_camera_rotations(str(tmp_path / "none.npz"), _video())
    with pytest.raises(UsageError, match="no ground-truth cameras"):
        load_camera_rotations("gt", _video())


SMALL = {
    "fit_size": 48,
    "stage1": {"iters": 4, "batch": 6},
    "stage2": {"iters": 4, "batch": 4},
    "camera": {"azimuths": 6, "elevations": [10.0]},
    "max_frames": 12,
}


def test_fit_cli_with_known_cameras(orbit_video, tmp_path, monkeypatch, capsys):
    """`zooctl fit --cameras gt` and the same rotations from a file give the same fit; the record
    names them; a bad file is one clear line."""
    from zooctl.store.bank import Bank

    asset, folder = orbit_video
    store = tmp_path / "store"
    Bank(store).add(asset)
    monkeypatch.setenv("ZOOCTL_STORE", str(store))
    monkeypatch.chdir(tmp_path)
    cfg = tmp_path / "small.json"
    cfg.write_text(json.dumps(SMALL))
    with np.load(Path(folder) / "video.npz") as z:
        np.savez(tmp_path / "cams.npz", rotations=z["gt_cam_rotation"])
    base = ["fit", str(folder), "--template", "quadruped", "--config", str(cfg), "--json"]
    r = run_inprocess(capsys, *base, "--name", "a", "--cameras", "gt")
    assert r.code == 0, r.err
    a = json.loads((store / "fits" / "a" / "record.json").read_text())
    r = run_inprocess(capsys, *base, "--name", "b", "--cameras", str(tmp_path / "cams.npz"))
    assert r.code == 0, r.err
    b = json.loads((store / "fits" / "b" / "record.json").read_text())
    assert a["cameras"] == "gt" and b["cameras"] == str((tmp_path / "cams.npz").resolve())
    assert a["camera"] == b["camera"] and a["metrics"]["mask_iou"] == b["metrics"]["mask_iou"]
    assert "start_trial" not in a["camera"]["search"].get("view_trial", {})  # no track to choose
    from test_fit_e2e import validate_record

    validate_record(a)
    np.savez(tmp_path / "short.npz", rotations=np.stack([np.eye(3)] * 3))
    r = run_inprocess(capsys, *base, "--name", "c", "--cameras", str(tmp_path / "short.npz"))
    assert r.code != 0
    assert "camera rotations of shape (3, 3, 3) for a video of 12 frames" in r.err
    assert "Traceback" not in r.err
