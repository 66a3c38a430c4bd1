"""A long clip fitted in windows (`FitConfig.window_frames`): the first window fits the body and
the camera, later windows hold them and what came before them, and continue from it."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch
from fit_helpers import tiny_fit_config

PER_FRAME = ("rotations", "root_rotation", "root_translation")


@pytest.mark.parametrize("T", [1, 60, 100, 101, 240, 300, 301, 1000])
def test_windows_cover_the_clip_once_in_order(T):
    cfg = tiny_fit_config()
    spans = cfg.windows(T)
    assert spans[0][0] == 0 and spans[-1][1] == T
    assert all(a[1] == b[0] for a, b in zip(spans, spans[1:], strict=False))
    assert all(0 < e - s <= cfg.window_frames for s, e in spans)
    assert spans[0] == (0, min(T, cfg.window_frames))
    cfg.window_frames = 0
    assert cfg.windows(T) == [(0, T)]


@pytest.fixture(scope="module")
def long_fit(tmp_path_factory):
    """A 12-frame clip fitted in two windows of 6, every step's state kept: (video, template,
    config, result, states)."""
    from zooctl.benchdata.make import make_video
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.run import fit_video
    from zooctl.procedural import build_animal

    asset = build_animal("quadruped", name="quadruped")
    video = load_fit_video(make_video(asset, tmp_path_factory.mktemp("videos"), frames=12, size=64, seed=3))
    cfg = tiny_fit_config(iters=3)
    cfg.window_frames, cfg.checkpoint_every = 6, 1
    states: list[dict] = []
    result = fit_video(video, asset, cfg, checkpoint=lambda state: states.append(copy.deepcopy(state)))
    return video, asset, cfg, result, states


def test_the_first_window_is_the_fit_of_its_frames_alone_and_later_ones_move_only_theirs(long_fit):
    from zooctl.fit.run import fit_video

    video, asset, _, long, states = long_fit
    assert long.scene.num_frames == 12 and long.iou.shape == (12,) and np.isfinite(long.iou).all()
    assert [len(long.history[k]) for k in ("stage1", "stage2")] == [6, 6]  # 3 + 3 steps a stage
    short = fit_video(video.truncated(6), asset, tiny_fit_config(iters=3))
    fitted, alone = long.scene.state_dict(), short.scene.state_dict()
    for k, v in alone.items():  # bit for bit: the later window moved nothing of the first's
        assert torch.equal(fitted[k][:6] if k in PER_FRAME else fitted[k], v), k
    assert long.camera_init == short.camera_init and long.scale == short.scale
    later = [s for s in states if s.get("window") == 1]
    assert later and later[0]["stage"] == 1 and later[0]["iteration"] == 0  # a resume starts the window
    for k in PER_FRAME:
        assert not torch.equal(fitted[k][6:], later[0]["scene"][k][6:]), k


def test_a_long_fit_resumes_from_the_start_of_its_later_window(long_fit):
    from zooctl.fit.run import fit_video

    video, asset, cfg, whole, states = long_fit
    at = next(s for s in states if s.get("window") == 1)
    resumed = fit_video(video, asset, cfg, resume=at)
    for k, v in whole.scene.state_dict().items():
        assert torch.allclose(resumed.scene.state_dict()[k], v, atol=1e-6), k


def test_fits_of_one_long_video_share_its_first_window_and_its_flow_targets(long_fit, monkeypatch):
    """The template trials fit the same video several times: its first window's flow targets are
    made once."""
    import dataclasses

    import zooctl.fit.inputs as inputs
    from zooctl.fit.run import fit_video

    video, asset, cfg, _, _ = long_fit
    video = dataclasses.replace(video, cache={})
    calls = []
    real = inputs._resample_flow
    monkeypatch.setattr(inputs, "_resample_flow", lambda *a: calls.append(len(a[0].masks)) or real(*a))
    for _ in range(2):
        fit_video(video, asset, cfg, pause_at=1)
    assert calls == [6]


def _runner(T=12, span=None):
    from zooctl.fit.config import preset
    from zooctl.fit.losses import MaskTargets
    from zooctl.fit.scene import FitScene
    from zooctl.fit.stages import StageRunner, Targets
    from zooctl.rig.synthetic import tube_asset

    asset = tube_asset(bones=3, rings_per_bone=2, segments=8, bone_length=0.3, radius=0.05)
    torch.manual_seed(0)
    scene = FitScene(asset, T, 16, 16, focal=20.0, hidden=8)
    with torch.no_grad():
        scene.root_translation[:, 2] = -2.0
    masks = np.zeros((T, 16, 16), np.float32)
    masks[:, 4:12, 3:13] = 1.0
    cfg = preset("fast")
    cfg.stage2.batch = 4
    return scene, cfg, StageRunner(scene, Targets(MaskTargets.build(masks, seed=0)), cfg, 2, span)


def test_a_step_moves_only_the_frames_of_its_window_and_never_held_ones():
    """Lazy Adam: a frame outside the step's window (or held, before the span) keeps its exact
    values even with momentum from earlier steps."""
    from zooctl.fit.stages import make_optimizer

    scene, cfg, runner = _runner(span=(4, 12))
    opt = make_optimizer(scene, cfg, 2, learn_focal=False, shared=True)
    for it in range(6):
        before = [p.detach().clone() for p in scene.per_frame_parameters()]
        runner.gen, runner._queue = np.random.default_rng(it), []
        window = runner.window()  # the window the step will draw: the same generator state again
        runner.gen, runner._queue = np.random.default_rng(it), []
        terms = runner.step(opt, it)
        assert set(terms) >= {"mask", "total"} and all(t.dim() == 0 for t in terms.values())
        inside = torch.zeros(scene.num_frames, dtype=torch.bool)
        inside[window[window >= 4]] = True
        for p, b in zip(scene.per_frame_parameters(), before, strict=True):
            assert torch.equal(p.detach()[~inside], b[~inside])
            assert not torch.equal(p.detach()[inside], b[inside])


def test_the_term_log_reads_steps_back_in_batches_and_keeps_each_once():
    from zooctl.fit.stages import TermLog

    history, seen = [], []
    log = TermLog(history, seen.append, every=3)
    steps = [
        {"mask": torch.tensor(0.5 * i), "total": torch.tensor(float(i), dtype=torch.float64)}
        for i in range(7)
    ]
    for s in steps[:5]:
        log.add(s)
    assert len(history) == 3 and seen == history  # the first three, read back together
    log.flush()
    assert history == [{"mask": 0.5 * i, "total": float(i)} for i in range(5)]

    def stop(row):
        raise KeyboardInterrupt

    log.on_step = stop
    log.add(steps[5])
    with pytest.raises(KeyboardInterrupt):
        log.flush()
    log.flush()  # what a checkpoint after Ctrl-C does: nothing is added twice
    assert [r["total"] for r in history] == [0, 1, 2, 3, 4, 5]


def test_a_longer_body_fitted_in_windows_is_lengthened_once_and_held_after(long_fit):
    """``length`` (the template trials' longer body) lengthens the first window's model; later
    windows hold that body, prior centre included, and move only their own frames."""
    from zooctl.fit.run import fit_video

    video, asset, cfg, _, _ = long_fit
    longer = fit_video(video, asset, cfg, length=1.3)
    first = fit_video(video.truncated(6), asset, tiny_fit_config(iters=3), length=1.3)
    assert longer.scene.num_frames == 12 and np.isfinite(longer.iou).all()
    centre = longer.scene.model.bone_centre
    assert centre.max() > 0.1  # a spine's bones started 1.3 times longer
    fitted, alone = longer.scene.state_dict(), first.scene.state_dict()
    for k, v in alone.items():
        assert torch.equal(fitted[k][:6] if k in PER_FRAME else fitted[k], v), k
