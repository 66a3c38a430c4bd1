"""Hard inputs: empty masks on some frames, the animal leaving the frame, one frame, bad templates,
bad options, and Ctrl-C followed by --resume. Tiny sizes and few iterations: correctness, not quality."""

from __future__ import annotations

import json

import numpy as np
import pytest
from cli_helpers import run_inprocess
from fit_helpers import tiny_fit_config, tiny_overrides

from zooctl.errors import InputError, NotFoundError, UsageError
from zooctl.fit.config import FitConfig, load_config, preset
from zooctl.fit.inputs import FitVideo
from zooctl.fit.run import fit_video


@pytest.fixture(scope="module")
def tube_video(tmp_path_factory):
    """A 2-bone tube rendered in a 6-frame, 48 px benchmark video (and the tube itself)."""
    from zooctl.benchdata.make import make_video
    from zooctl.fit.inputs import load_bench_video
    from zooctl.rig.synthetic import tube_asset

    asset = tube_asset(bones=3, name="tube")
    folder = make_video(asset, tmp_path_factory.mktemp("tube"), frames=6, size=48, seed=1)
    return asset, load_bench_video(folder), folder


def tiny() -> FitConfig:
    return tiny_fit_config(iters=3)


def test_empty_masks_and_out_of_frame(tube_video):
    asset, video, _ = tube_video
    masks = video.masks.copy()
    masks[2] = False  # the animal hidden or out of frame on two frames
    masks[3] = False
    v = FitVideo("gappy", video.frames, masks, flow=video.flow, flow_valid=video.flow_valid)
    res = fit_video(v, asset, tiny())
    assert np.isnan(res.iou[2]) and np.isnan(res.iou[3])
    assert np.all(np.isfinite(res.iou[[0, 1, 4, 5]]))
    tr = res.scene.root_translation.detach().numpy()
    assert np.all(np.isfinite(tr))  # the hidden frames are interpolated, not sent to infinity
    gap = np.linalg.norm(tr[2] - 0.5 * (tr[1] + tr[4]))
    assert gap < asset.size()


def test_single_frame(tube_video):
    asset, video, _ = tube_video
    v = FitVideo("still", video.frames[:1], video.masks[:1])
    res = fit_video(v, asset, tiny())
    assert res.scene.num_frames == 1 and res.iou.shape == (1,) and res.iou[0] > 0.3


def test_all_masks_empty_is_a_clear_error(tube_video):
    asset, video, _ = tube_video
    with pytest.raises(InputError, match="every mask is empty"):
        fit_video(FitVideo("none", video.frames, np.zeros_like(video.masks)), asset, tiny())


def test_mask_count_mismatch_is_a_clear_error(tube_video):
    asset, video, _ = tube_video
    with pytest.raises(InputError, match="masks"):
        FitVideo("bad", video.frames, video.masks[:2]).check()


def test_config_errors(tmp_path):
    with pytest.raises(UsageError):
        preset("slow")
    bad = tmp_path / "c.json"
    bad.write_text('{"stage2": {"itres": 3}}')
    with pytest.raises(InputError, match="itres"):
        load_config(bad)
    bad.write_text("{not json")
    with pytest.raises(InputError):
        load_config(bad)
    with pytest.raises(UsageError):
        FitConfig.from_dict({"fit_size": 4})
    with pytest.raises(UsageError, match=r"stage2.lr_joints 0 must be > 0") as err:
        FitConfig.from_dict({"stage2": {"lr_joints": 0}})
    assert "joint rotations" in err.value.hint
    cfg = FitConfig.from_dict(json.loads(preset("quality").to_json()))
    assert cfg.to_dict() == preset("quality").to_dict()


def test_joint_rotations_have_their_own_learning_rate(tube_video):
    from zooctl.fit.scene import FitScene
    from zooctl.fit.stages import make_optimizer

    asset = tube_video[0]
    scene = FitScene(asset, 4, 32, 32, focal=40.0)
    cfg = tiny_fit_config()
    cfg.stage2.lr, cfg.stage2.lr_joints = 0.03, 0.01

    def rates() -> dict[int, float]:
        opt = make_optimizer(scene, cfg, 2, learn_focal=False)
        return {id(p): g["lr"] for g in opt.param_groups for p in g["params"]}

    assert rates()[id(scene.rotations)] == 0.01 and rates()[id(scene.root_rotation)] == 0.03
    cfg.stage2.lr_joints = None
    assert rates()[id(scene.rotations)] == 0.03


def test_a_named_template_steps_its_joints_at_the_given_rate(tube_video, store):
    from zooctl.fit.job import fit_job
    from zooctl.store.bank import Bank

    asset, _, folder = tube_video
    Bank(store).add(asset)
    cfg = tiny_fit_config()
    assert (cfg.stage2.lr_joints, cfg.stage2.lr_joints_given) == (0.02, 0.01)  # --preset fast
    quality = preset("quality").for_named_template().stage2
    assert quality.lr_joints == 0.01 and preset("quality").stage2.lr_joints == 0.02  # as fast
    named = cfg.for_named_template()
    assert named.stage2.lr_joints == 0.01 and cfg.stage2.lr_joints == 0.02  # a copy
    rec = fit_job(str(folder), store, cfg, name="t", template="tube", outputs=("loss",))
    assert rec["config"]["stage2"]["lr_joints"] == 0.01  # the record keeps the rate used
    cfg.stage2.lr_joints_given = None
    assert cfg.for_named_template().stage2.lr_joints == 0.02
    # A config that sets the joints' rate alone sets it for named templates too.
    own = FitConfig.from_dict({"stage2": {"lr_joints": 0.005}}).for_named_template()
    assert own.stage2.lr_joints == 0.005
    both = FitConfig.from_dict({"stage2": {"lr_joints": 0.005, "lr_joints_given": 0.002}})
    assert both.for_named_template().stage2.lr_joints == 0.002
    with pytest.raises(UsageError, match=r"stage2.lr_joints_given -0.01 must be > 0"):
        FitConfig.from_dict({"stage2": {"lr_joints_given": -0.01}})


def test_the_quality_preset_is_the_fast_one_fitted_longer():
    """Quality's own search, trials, fit size and field made a worse 3D (BENCHMARKS.md, "The
    quality preset"): it differs from fast in stage 2's length alone."""
    fast, quality = preset("fast").to_dict(), preset("quality").to_dict()
    assert quality["stage2"].pop("iters") == 2400 and fast["stage2"].pop("iters") == 1000
    assert (quality.pop("preset"), fast.pop("preset")) == ("quality", "fast")
    assert quality == fast


def test_the_shape_rate_of_a_named_template_a_retrieved_one_and_the_trials():
    """A retrieved template's fit frees its shape after the trials (BENCHMARKS.md, "The shape
    freer for the winner only"); a named one and the trials keep 1e-3."""
    for name in ("fast", "quality"):
        cfg = preset(name)
        assert (cfg.stage2.lr_shape, cfg.stage2.lr_shape_given, cfg.trials.lr_shape) == (5e-3, 1e-3, 1e-3)
        assert cfg.for_named_template().stage2.lr_shape == 1e-3 and cfg.for_trials().stage2.lr_shape == 1e-3
        assert cfg.stage2.lr_shape == 5e-3  # copies
    # A config that sets the shape's rate alone sets it for named templates and the trials too.
    alone = FitConfig.from_dict({"stage2": {"lr_shape": 0.002}})
    assert alone.for_named_template().stage2.lr_shape == alone.for_trials().stage2.lr_shape == 0.002
    given = FitConfig.from_dict(
        {"stage2": {"lr_shape": 0.002, "lr_shape_given": 0.0005}, "trials": {"lr_shape": 0.003}}
    )
    assert (given.for_named_template().stage2.lr_shape, given.for_trials().stage2.lr_shape) == (0.0005, 0.003)
    assert given.for_trials().stage2.lr_joints == given.stage2.lr_joints  # the shape's rate alone
    with pytest.raises(UsageError, match=r"trials.lr_shape 0 must be > 0"):
        FitConfig.from_dict({"trials": {"lr_shape": 0}})


def test_cli_errors_are_one_line(tube_video, store, capsys, tmp_path):
    _, _, folder = tube_video
    r = run_inprocess(capsys, "fit", str(folder), "--template", "nope")
    assert r.code == 2 and "error:" in r.err and "Traceback" not in r.err
    r = run_inprocess(capsys, "fit", str(tmp_path / "missing.mp4"), "--template", "x")
    assert r.code == 2 and "error:" in r.err
    r = run_inprocess(capsys, "fit", str(folder), "--preset", "slow")
    assert r.code == 2 and "preset" in r.err
    r = run_inprocess(capsys, "fit", str(folder))  # empty bank, no --template
    assert r.code == 2 and "bank" in r.err


class StopAt:
    """A reporter that presses Ctrl-C at stage 2's step that is the ``at``-th step of the fit."""

    def __init__(self, at: int) -> None:
        self.n, self.at = 0, at

    def stage(self, name, total, done=0):
        self.name = name

    def step(self, terms):
        self.n += 1
        if self.name == "stage2" and self.n == self.at:
            raise KeyboardInterrupt

    def message(self, text):
        pass


def interrupt_at_stage2_step_4(folder, store, cfg, name: str) -> None:
    """Fit ``folder`` with the tube template as ``name``, Ctrl-C at stage 2's 4th step."""
    from zooctl.fit.job import fit_job

    with pytest.raises(KeyboardInterrupt):
        fit_job(
            str(folder),
            store,
            cfg,
            name=name,
            template="tube",
            reporter=StopAt(cfg.stage1.iters + 4),
            outputs=("loss",),
        )


def test_interrupt_then_resume(tube_video, store, tmp_path):
    """Ctrl-C mid stage 2 keeps the store intact and --resume finishes the same fit (the
    smoothness weight's decay, too, goes on from where it stopped)."""
    from zooctl.fit.job import fit_job
    from zooctl.store.bank import Bank
    from zooctl.store.fits import FitStore

    asset, _, folder = tube_video
    Bank(store).add(asset)
    cfg = tiny()
    cfg.stage2.iters = 6
    cfg.checkpoint_every = 2
    cfg.weights.smooth_start, cfg.weights.smooth_until = 1000.0, 1.0
    cfg.camera.start_trial = "none"  # stage 2 itself interrupted (`start_trial`: a test of its own)

    interrupt_at_stage2_step_4(folder, store, cfg, "t")
    fits = FitStore(store)
    assert fits.get("t")["status"] == "interrupted"
    st = fits.load_state("t")
    assert st["stage"] == 2 and st["iteration"] == 4  # the 4th step ran before Ctrl-C
    rec = fit_job(str(folder), store, name="t", resume=True, outputs=("loss",))
    assert rec["status"] == "done"
    assert rec["losses"]["stage2"]["steps"] == 6 and rec["losses"]["stage1"]["steps"] == 3
    whole = fit_job(str(folder), store, cfg, name="u", template="tube", outputs=("loss",))
    last, whole_last = rec["losses"]["stage2"]["last"], whole["losses"]["stage2"]["last"]
    assert last["smooth"] == pytest.approx(whole_last["smooth"], rel=1e-3)
    with pytest.raises(NotFoundError):
        fit_job(str(folder), store, name="never", resume=True)


def test_sigterm_saves_like_ctrl_c(tube_video, store, tmp_path):
    """A `zooctl fit` process sent SIGTERM (a scheduler's cancel) exits 143 with its record marked
    interrupted and its stage-2 state saved for --resume, as Ctrl-C leaves it."""
    import os
    import signal
    import subprocess
    import sys
    import time

    from zooctl.store.bank import Bank
    from zooctl.store.fits import FitStore

    asset, _, folder = tube_video
    Bank(store).add(asset)
    conf = tmp_path / "c.json"
    over = tiny_overrides(3)
    over["stage2"]["iters"] = 100_000  # runs until it is stopped
    over["checkpoint_every"] = 5
    conf.write_text(json.dumps(over))
    env = dict(os.environ, ZOOCTL_STORE=str(store))
    cmd = [sys.executable, "-m", "zooctl", "fit", str(folder), "--template", "tube", "--name", "t"]
    proc = subprocess.Popen(cmd + ["--config", str(conf)], env=env, stderr=subprocess.PIPE, text=True)
    fits = FitStore(store)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if _state_saved(fits, "t"):
            break
        time.sleep(0.2)
    assert proc.poll() is None, proc.stderr.read()
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 143, err
    assert "terminated" in err and "Traceback" not in err
    assert fits.get("t")["status"] == "interrupted"
    assert fits.load_state("t")["stage"] == 2


def _state_saved(fits, name: str) -> bool:
    try:
        return fits.load_state(name)["stage"] == 2
    except Exception:
        return False


def test_ctrl_c_says_interrupted(tube_video, store, capsys, monkeypatch):
    """Ctrl-C inside a command: exit 130 and one line saying so (Click alone exits without it)."""
    import zooctl.fit.job as job

    def stop(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(job, "fit_job", stop)
    _, _, folder = tube_video
    r = run_inprocess(capsys, "fit", str(folder), "--template", "tube")
    assert r.code == 130 and r.err.strip().endswith("interrupted") and "Traceback" not in r.err


def test_a_state_paused_before_girths_existed_resumes_as_it_started(tube_video, store, tmp_path):
    """A stage-2 state saved by a zooctl without girths (its config names none, its optimiser has
    no girth parameter) resumes without them, as the fit it was."""
    from zooctl.fit.job import fit_job
    from zooctl.store.bank import Bank
    from zooctl.store.fits import FitStore

    asset, _, folder = tube_video
    Bank(store).add(asset)
    cfg = tiny()
    cfg.stage2.iters = 6
    cfg.checkpoint_every = 2
    cfg.ablation.girth = False
    cfg.camera.start_trial = "none"

    interrupt_at_stage2_step_4(folder, store, cfg, "old")
    fits = FitStore(store)
    st = fits.load_state("old")
    assert st["stage"] == 2 and not any("girth" in k for k in st["scene"])
    del st["config"]["ablation"]["girth"]  # as saved before the switch existed
    fits.save_state("old", st)
    rec = fit_job(str(folder), store, name="old", resume=True, outputs=("loss",))
    assert rec["status"] == "done" and rec["config"]["ablation"]["girth"] is False
