"""The steady-turn track (``camera.track``) and the start trial (``camera.start_trial``): a
named template's fit also starts from a steady turn, and goes on from the start whose loss is
lower at the trials' pause."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from test_fit_known_camera import _rotation_error_deg

from zooctl.benchdata.make import make_video
from zooctl.fit.camera_init import SilhouetteScorer, initialise_camera, view_rotation
from zooctl.fit.config import CameraConfig, FitConfig
from zooctl.fit.named_start import start_trial
from zooctl.fit.scene import CAMERA_ROTATION
from zooctl.fit.view_trial import trial_loss
from zooctl.geometry import quat_to_matrix
from zooctl.rig.synthetic import tube_asset

pytestmark = pytest.mark.usefixtures("one_thread")

TINY = {
    "fit_size": 32,
    "stage1": {"iters": 4, "batch": 4},
    "stage2": {"iters": 6, "batch": 3},
    "camera": {
        "azimuths": 4,
        "elevations": [10.0],
        "search_size": 32,
        "start_trial": "steady",
        "start_trial_at": 5,
    },
    "trials": {"iters": 3},
}


def _turning_masks(asset, az0: float, el: float, per_frame: float, frames: int, size: int, focal: float):
    """Masks (T, size, size) of the rigid rest template turning steadily about its up axis."""
    scorer = SilhouetteScorer(asset.vertices, asset.faces, np.zeros((frames, size, size), bool), size)
    rest = asset.vertices - 0.5 * (asset.vertices.max(0) + asset.vertices.min(0))
    depth = 3.0 * float(np.ptp(rest, axis=0).max())
    return np.stack(
        [
            scorer.silhouette(rest @ view_rotation(az0 + per_frame * t, el).T + [0.0, 0.0, -depth], focal)
            for t in range(frames)
        ]
    )


@pytest.mark.parametrize("per_frame", [2.5, -1.5])
def test_the_steady_track_turns_with_a_steadily_turning_body(per_frame):
    """A rigid body turning steadily: the steady track's roots turn with it, first frame to last,
    and every keyframe stays near the truth (the turn's sign reversed fails this)."""
    from zooctl.procedural import build_animal

    asset = build_animal("quadruped", name="quadruped")
    frames, size, focal = 36, 96, 110.0
    masks = _turning_masks(asset, 30.0, 20.0, per_frame, frames, size, focal)
    cfg = CameraConfig(focal=focal, azimuths=12, elevations=[-15.0, 10.0, 35.0], track="steady")
    init = initialise_camera(asset.vertices, asset.faces, masks, cfg, 1.0)
    truth = [CAMERA_ROTATION @ view_rotation(30.0 + per_frame * t, 20.0) for t in range(frames)]
    fitted = [CAMERA_ROTATION @ quat_to_matrix(q) for q in init.root_rotation]
    assert abs(_rotation_error_deg(fitted[0], fitted[-1]) - abs(per_frame) * (frames - 1)) < 15.0
    assert max(_rotation_error_deg(fitted[t], truth[t]) for t in range(0, frames, 6)) < 20.0
    assert min(init.keyframe_iou) > 0.7


def test_trial_loss_is_the_mean_of_the_last_iterations():
    state = {"history": {"stage2": [{"total": float(x)} for x in range(100)]}}
    assert trial_loss(state) == pytest.approx(np.mean(range(50, 100)))
    assert trial_loss(state, last=10) == pytest.approx(94.5)
    assert trial_loss({"history": {"stage2": []}}) == math.inf and trial_loss(None) == math.inf


def test_the_start_trial_keeps_the_start_of_lower_loss_and_the_fit_goes_on_from_it(tmp_path):
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.run import fit_video

    thin = tube_asset(bones=3, name="thin")
    video = load_fit_video(make_video(thin, tmp_path / "v", frames=6, size=32, seed=0))
    cfg = FitConfig.from_dict(json.loads(json.dumps(TINY)))
    kept = start_trial(video, thin, cfg)
    info = kept.view["start_trial"]
    losses = info["loss"]
    assert set(losses) == {"greedy", "steady"} and all(np.isfinite(list(losses.values())))
    assert info["kept"] == min(losses, key=losses.get) and info["extra_seconds"] > 0
    # compared past the trials' pause (where each start's mirror check is), as configured
    assert cfg.trials.iters < cfg.camera.start_trial_at < cfg.stage2.iters
    assert kept.state["iteration"] == info["at"] == cfg.camera.start_trial_at
    assert trial_loss(kept.state) == pytest.approx(losses[info["kept"]], abs=1e-5)
    assert kept.state["camera_init"]["view_trial"]["start_trial"] == info
    done = fit_video(video, thin, cfg, resume=kept.state)
    assert len(done.history["stage2"]) == cfg.stage2.iters
    # the kept start's own fit, unpaused, is the same fit
    track = dataclasses.replace(cfg, camera=dataclasses.replace(cfg.camera, track=info["kept"]))
    whole = fit_video(video, thin, track)
    np.testing.assert_allclose(done.iou, whole.iou, atol=1e-6)


def test_the_two_starts_side_by_side_are_the_two_one_after_another(tmp_path):
    """With two torch threads the two starts run at once, one process of one thread each
    (`zooctl.fit.trial_pool`): the same losses, the same start kept and the same paused state as
    one after another on one thread."""
    import torch
    from test_fit_trial_pool import _Recorder, _threads

    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.trial_pool import trial_threads

    thin = tube_asset(bones=3, name="thin")
    video = load_fit_video(make_video(thin, tmp_path / "v", frames=6, size=32, seed=0))
    cfg = FitConfig.from_dict(json.loads(json.dumps(TINY)))
    runs = []
    for threads in (1, 2):
        assert bool(trial_threads(cfg, 2, threads=threads)) == (threads == 2)
        rep = _Recorder()
        with _threads(threads):
            runs.append((start_trial(video, thin, cfg, rep), rep))
    (one, _), (two, rep) = runs
    a, b = one.view["start_trial"], two.view["start_trial"]
    assert a["kept"] == b["kept"] and a["at"] == b["at"] and b["extra_seconds"] > 0
    for k in ("greedy", "steady"):
        assert a["loss"][k] == pytest.approx(b["loss"][k], abs=1e-5)
    assert one.state["iteration"] == two.state["iteration"] == cfg.camera.start_trial_at
    for k, v in one.state["scene"].items():
        assert torch.allclose(v, two.state["scene"][k], atol=1e-5), k
    # the workers' bars come through named by their start; which start's bar a stage shows is a
    # race (`_Forwarder` shows one trial's stage at a time), so either may hold all of them
    assert rep.stages and all("(greedy turn)" in s or "(steady turn)" in s for s in rep.stages)


def test_fit_with_a_named_template_records_the_start_trial(tmp_path, store, capsys):
    from test_fit_view_trial import fit_named_tube

    rec = fit_named_tube(tmp_path, store, capsys, TINY, frames=6)
    view = rec["camera"]["search"]["view_trial"]
    assert view["start_trial"]["kept"] in ("greedy", "steady")
    assert rec["timings"]["mirror_trial"] == view["extra_seconds"]
    assert rec["losses"]["stage2"]["steps"] == TINY["stage2"]["iters"]


def _tiny_without_start_trial(**camera) -> dict:
    return dict(TINY, camera=dict({k: v for k, v in TINY["camera"].items() if k != "start_trial"}, **camera))


def test_a_named_template_tries_both_starts_by_default(tmp_path, store, capsys):
    from test_fit_view_trial import fit_named_tube

    assert CameraConfig().track == "greedy" and CameraConfig().start_trial == "steady"
    rec = fit_named_tube(tmp_path, store, capsys, _tiny_without_start_trial(), frames=6)
    assert rec["config"]["camera"]["start_trial"] == "steady"
    assert rec["camera"]["search"]["view_trial"]["start_trial"]["kept"] in ("greedy", "steady")


def test_start_trial_none_keeps_the_greedy_track_alone(tmp_path, store, capsys):
    from test_fit_view_trial import fit_named_tube

    rec = fit_named_tube(tmp_path, store, capsys, _tiny_without_start_trial(start_trial="none"), frames=6)
    assert "start_trial" not in rec["camera"]["search"]["view_trial"]


def test_the_saved_state_is_the_kept_starts(tmp_path, store):
    """Both starts run to the pause saving their states as they go (the steady one last); the
    state a fit leaves for --resume and the benchmarks is the kept start's."""
    from zooctl.fit.job import fit_job
    from zooctl.store.bank import Bank
    from zooctl.store.fits import FitStore

    thin = tube_asset(bones=3, name="thin")
    Bank(store).add(thin)
    folder = make_video(thin, tmp_path / "v", frames=6, size=32, seed=0)
    cfg = FitConfig.from_dict(_tiny_without_start_trial())
    cfg.trials.iters = cfg.stage2.iters  # the trials are the whole of stage 2
    cfg.checkpoint_every = 1
    rec = fit_job(str(folder), store, cfg, name="k", template="thin", outputs=())
    kept = rec["camera"]["search"]["view_trial"]["start_trial"]["kept"]
    assert kept == "greedy"  # this video's: the case where the last state saved was the other's
    assert FitStore(store).load_state("k")["config"]["camera"]["track"] == kept


@pytest.mark.parametrize("stop_in", ["greedy", "steady"])
def test_a_fit_stopped_inside_the_start_trials_tries_them_again_on_resume(tmp_path, store, stop_in):
    """Ctrl-C inside either start's trial leaves a state that --resume does not just finish: the
    trials run again, so the resumed fit keeps the start, config and fit an uninterrupted one does."""
    from test_fit_robustness import StopAt

    from zooctl.fit.job import START_TRIALS, fit_job
    from zooctl.store.bank import Bank
    from zooctl.store.fits import FitStore

    thin = tube_asset(bones=3, name="thin")
    Bank(store).add(thin)
    folder = make_video(thin, tmp_path / "v", frames=6, size=32, seed=0)
    cfg = FitConfig.from_dict(_tiny_without_start_trial())
    cfg.checkpoint_every = 1
    whole = fit_job(str(folder), store, cfg, name="whole", template="thin", outputs=("loss",))
    # the 2nd stage-2 step of the first trial (greedy), or of the second (steady): stage 1 and
    # the first start's stage-2 steps (to start_trial_at) before it
    per_trial = cfg.stage1.iters + cfg.camera.start_trial_at
    at = cfg.stage1.iters + 2 + (per_trial if stop_in == "steady" else 0)
    with pytest.raises(KeyboardInterrupt):
        fit_job(str(folder), store, cfg, name="cut", template="thin", reporter=StopAt(at), outputs=("loss",))
    fits = FitStore(store)
    saved = fits.load_state("cut")
    assert saved[START_TRIALS] == {"template_given": True} and saved["config"] == whole["config"]
    rec = fit_job(str(folder), store, name="cut", resume=True, outputs=("loss",))
    assert rec["status"] == "done" and rec["config"] == whole["config"]
    view, whole_view = rec["camera"]["search"]["view_trial"], whole["camera"]["search"]["view_trial"]
    assert view["start_trial"]["loss"] == whole_view["start_trial"]["loss"]
    assert view["start_trial"]["kept"] == whole_view["start_trial"]["kept"]
    assert rec["losses"]["stage2"]["last"]["total"] == pytest.approx(
        whole["losses"]["stage2"]["last"]["total"], rel=1e-4
    )
    assert START_TRIALS not in fits.load_state("cut")  # the finished fit's state: no trial to redo
