"""Template trials: retrieval's best candidates each get a short fit and the best-fitting one wins."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_fit_e2e import validate_record

from zooctl.benchdata.make import make_video
from zooctl.fit.config import FitConfig
from zooctl.fit.template import TRIAL_NOISE, close_trials_note
from zooctl.rig.synthetic import tube_asset

TINY = {
    "fit_size": 32,
    "stage1": {"iters": 4, "batch": 4},
    "stage2": {"iters": 3, "batch": 3},
    "camera": {"azimuths": 4, "elevations": [10.0], "search_size": 32},
    "trials": {"candidates": 2, "iters": 2},
}


def _bank_with_views(store):
    from zooctl.retrieval.index import index_asset
    from zooctl.store.bank import Bank

    bank = Bank(store)
    thin = tube_asset(bones=3, name="thin")
    for a in (thin, tube_asset(bones=2, bone_length=0.5, radius=0.6, name="fat")):
        bank.add(a)
        index_asset(bank, a, ["silhouette"], n_views=3, size=48)
    return bank, thin


def _fat_then_thin(bank, video, **sections):
    """`try_candidates` of fat then thin under TINY with ``sections`` merged in: (config, template,
    candidates, state)."""
    from zooctl.fit.template import try_candidates

    data = json.loads(json.dumps(TINY))
    for name, values in sections.items():
        data[name] |= values
    cfg = FitConfig.from_dict(data)
    cands = [{"name": "fat", "score": -2.0}, {"name": "thin", "score": -1.0}]
    return (cfg, *try_candidates(bank, video, cands, cfg))


def test_trials_pick_the_template_whose_fit_matches_best(tmp_path, store):
    """Handed the wrong template first, the trial fits still choose the animal of the video."""
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.template import try_candidates

    bank, thin = _bank_with_views(store)
    video = load_fit_video(make_video(thin, tmp_path / "v", frames=3, size=32, seed=0))
    video.masks[1] = False  # an empty mask (the animal left the frame) has no IoU: ignored
    cfg = FitConfig.from_dict(json.loads(json.dumps(TINY)))
    cands = [{"name": "fat", "score": -2.0}, {"name": "thin", "score": -1.0}]
    asset, out, state = try_candidates(bank, video, cands, cfg)
    assert asset.name == "thin"
    assert state["stage"] == 2 and state["iteration"] == 2 and len(state["history"]["stage2"]) == 2
    assert out[1]["trial_iou"] > out[0]["trial_iou"] and 0 <= out[0]["trial_iou"] <= 1
    assert cfg.stage2.iters == 3 and cfg.trials.candidates == 2  # the caller's config is untouched
    one = FitConfig.from_dict({**json.loads(json.dumps(TINY)), "trials": {"candidates": 1}})
    fresh = [{"name": "fat", "score": -2.0}, {"name": "thin", "score": -1.0}]
    asset, out, state = try_candidates(bank, video, fresh, one)
    assert asset.name == "fat" and "trial_iou" not in out[0] and state is None  # one candidate: no trial fits


def test_a_margin_keeps_retrievals_order_among_near_equal_trials(tmp_path, store):
    """``trials.margin``: a later candidate wins only by more than the margin; the state handed on
    is the winner's own trial."""
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.run import fit_video
    from zooctl.fit.template import pick_trial, try_candidates

    assert pick_trial([0.80, 0.83, 0.81]) == 1
    assert pick_trial([0.80, 0.83, 0.81], margin=0.02) == 1  # beaten by 0.03
    assert pick_trial([0.82, 0.83, 0.81], margin=0.02) == 0
    assert pick_trial([0.70, 0.83, 0.82], margin=0.02) == 1  # the first within the margin
    assert pick_trial([0.5, 0.5]) == 0  # ties keep the retrieval order
    bank, thin = _bank_with_views(store)
    video = load_fit_video(make_video(thin, tmp_path / "v", frames=3, size=32, seed=0))
    cfg = FitConfig.from_dict(
        {**json.loads(json.dumps(TINY)), "trials": {"candidates": 2, "iters": 2, "margin": 0.99}}
    )
    cands = [{"name": "fat", "score": -2.0}, {"name": "thin", "score": -1.0}]
    asset, out, state = try_candidates(bank, video, cands, cfg)
    assert out[1]["trial_iou"] > out[0]["trial_iou"]  # thin fits better, within the margin
    assert asset.name == "fat"
    again = fit_video(video, asset, cfg, resume=state)  # fat's trial: another's state would not load
    assert len(again.history["stage2"]) == cfg.stage2.iters


def test_the_full_fit_continues_the_winning_trial(tmp_path, store):
    """A trial is the start of the full fit, paused: continuing the winner's trial gives the same
    fit as one run from scratch, without searching the camera or running stage 1 again."""
    import torch

    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.run import fit_video
    from zooctl.fit.template import try_candidates

    bank, thin = _bank_with_views(store)
    video = load_fit_video(make_video(thin, tmp_path / "v", frames=3, size=32, seed=0))
    tiny = json.loads(json.dumps(TINY))
    tiny["trials"]["lr_shape"] = None  # the trials at stage 2's own shape rate: the fit's start
    cfg = FitConfig.from_dict(tiny)
    cands = [{"name": "fat", "score": -2.0}, {"name": "thin", "score": -1.0}]
    asset, _, state = try_candidates(bank, video, cands, cfg)
    trial_steps = list(state["history"]["stage2"])
    continued = fit_video(video, asset, cfg, resume=state)
    scratch = fit_video(video, asset, FitConfig.from_dict(tiny))
    assert len(trial_steps) == 2 and continued.history["stage2"][:2] == trial_steps
    view = continued.camera_init.pop("view_trial")  # what the trial tried: its start only here
    assert view["start"] == "search" and "trial_iou" not in view
    # the winner's trial ran again held, from its trial's search at box (`trials.depth`)
    assert continued.camera_init.pop("search_reused_from_depth") == "box"
    assert continued.history == scratch.history and continued.camera_init == scratch.camera_init
    a, b = continued.scene.state_dict(), scratch.scene.state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert "camera" not in continued.timings and "stage1" not in continued.timings  # not run again


def test_the_trials_fit_the_shape_at_their_own_rate_and_the_winner_goes_on_at_stage_twos(tmp_path, store):
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.run import fit_video

    bank, thin = _bank_with_views(store)
    video = load_fit_video(make_video(thin, tmp_path / "v", frames=3, size=32, seed=0))

    def trials(stage2_rate: float, trial_rate: float | None):
        cfg, asset, tried, state = _fat_then_thin(
            bank, video, stage2={"lr_shape": stage2_rate}, trials={"lr_shape": trial_rate, "workers": 1}
        )
        return cfg, asset, [c["trial_iou"] for c in tried], state

    slow_cfg, slow_asset, slow_ious, slow_state = trials(1e-3, 1e-3)
    free_cfg, free_asset, free_ious, free_state = trials(0.2, 1e-3)
    assert free_asset.name == slow_asset.name and free_ious == slow_ious  # stage 2's rate: not in the trials
    assert free_state["history"]["stage2"] == slow_state["history"]["stage2"]
    assert trials(0.2, None)[2] != slow_ious  # the trials' own rate is what they ran at

    def last_step(cfg, asset, state) -> float:
        before = state["scene"]["model.log_scale"].clone()
        after = fit_video(video, asset, cfg, resume=state).scene.state_dict()["model.log_scale"]
        return float((after - before).abs().max())

    assert last_step(free_cfg, free_asset, free_state) > 10 * last_step(slow_cfg, slow_asset, slow_state)


def test_a_trial_as_long_as_the_fit_is_the_fit(tmp_path, store):
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.run import fit_video

    bank, thin = _bank_with_views(store)
    video = load_fit_video(make_video(thin, tmp_path / "v", frames=3, size=32, seed=0))
    cfg = FitConfig.from_dict(json.loads(json.dumps(TINY)))
    trial = fit_video(video, thin, cfg, pause_at=10)
    assert len(trial.history["stage2"]) == cfg.stage2.iters and trial.paused["iteration"] == 3
    again = fit_video(video, thin, cfg, resume=trial.paused)
    assert len(again.history["stage2"]) == 3 and np.allclose(again.iou, trial.iou, equal_nan=True)


def test_fit_job_records_the_trials(tmp_path, store, monkeypatch):
    from zooctl.fit.job import fit_job

    monkeypatch.setenv("ZOOCTL_EMBEDDERS", "silhouette")
    bank, thin = _bank_with_views(store)
    folder = make_video(thin, tmp_path / "v", frames=3, size=32, seed=0)
    cfg = FitConfig.from_dict(json.loads(json.dumps(TINY)))
    rec = fit_job(str(folder), store, cfg, name="trial", bank=bank, outputs=("loss",))
    tried = [c for c in rec["retrieval"] if "trial_iou" in c]
    assert len(tried) == 2
    assert rec["template"] == max(tried, key=lambda c: c["trial_iou"])["name"]
    assert rec["timings"]["template_trials"] > 0
    assert rec["config"]["stage2"]["lr_joints"] == cfg.stage2.lr_joints  # retrieved: not lr_joints_given
    close = abs(tried[0]["trial_iou"] - tried[1]["trial_iou"]) <= TRIAL_NOISE
    assert any("could not tell" in n for n in rec["notes"]) == close
    validate_record(json.loads(open(rec["outputs"]["fit_json"]).read()))  # the file the fit writes
    assert np.isfinite(rec["metrics"]["mask_iou"])


def test_fit_job_notes_templates_the_trials_cannot_tell_apart(tmp_path, store, monkeypatch):
    from zooctl.fit.job import fit_job
    from zooctl.retrieval.index import index_asset

    monkeypatch.setenv("ZOOCTL_EMBEDDERS", "silhouette")
    bank, thin = _bank_with_views(store)
    twin = tube_asset(bones=3, name="twin")  # thin's shape under another name: the same trial
    bank.add(twin)
    index_asset(bank, twin, ["silhouette"], n_views=3, size=48)
    folder = make_video(thin, tmp_path / "v", frames=3, size=32, seed=0)
    rec = fit_job(str(folder), store, FitConfig.from_dict(json.loads(json.dumps(TINY))), name="t", bank=bank)
    other = ({"thin", "twin"} - {rec["template"]}).pop()
    assert [c["name"] for c in rec["retrieval"] if "trial_iou" in c] in (["thin", "twin"], ["twin", "thin"])
    (note,) = [n for n in rec["notes"] if "could not tell" in n]
    assert f"could not tell {rec['template']}" in note and f"--template {other}`" in note
    # a 32 px video's animal is too small to shape, and the record says so first
    assert "pixels a frame on average" in rec["notes"][0]


def test_a_close_call_between_trials_is_noted_for_the_user():
    cands = [
        {"name": "Wolf", "trial_iou": 0.80},
        {"name": "Trex", "trial_iou": 0.795},
        {"name": "Fox", "trial_iou": 0.70},
        {"name": "Cow"},  # not tried
    ]
    note = close_trials_note(cands, "Wolf", "'my dog.mp4'")
    assert "could not tell Wolf (trial IoU 0.800) from Trex (0.795)" in note and "Fox" not in note
    assert "`zooctl fit 'my dog.mp4' --template Trex`" in note
    assert close_trials_note(cands, "Fox", "v") is None  # the others fitted clearly better
    assert "could not tell Trex (trial IoU 0.795) from Wolf (0.800)" in close_trials_note(cands, "Trex", "v")
    cands[1]["trial_iou"] = 0.78
    assert close_trials_note(cands, "Wolf", "v") is None  # 0.02 apart: the trials told them apart
    assert close_trials_note([{"name": "Wolf"}], "Wolf", "v") is None  # no trials ran


def test_fit_cli_prints_the_trial_ious(tmp_path, store, capsys, monkeypatch):
    from cli_helpers import run_inprocess

    monkeypatch.setenv("ZOOCTL_EMBEDDERS", "silhouette")
    monkeypatch.chdir(tmp_path)
    _, thin = _bank_with_views(store)
    folder = make_video(thin, tmp_path / "v", frames=3, size=32, seed=0)
    (tmp_path / "tiny.json").write_text(json.dumps({**TINY, "stage2": {"iters": 4, "batch": 3}}))
    r = run_inprocess(capsys, "fit", str(folder), "--config", str(tmp_path / "tiny.json"), "--name", "t")
    assert r.code == 0, r.err
    assert r.out.count("trial IoU") == 2 and "fitted t with template thin" in r.out


def test_bench_run_counts_the_right_body_plans(tmp_path, store, monkeypatch):
    """With retrieval, every bench row says whether its template has the video's body plan, and
    the summary counts them at retrieval's top-1, among the tried candidates and after the trials."""
    from zooctl.benchdata.run import markdown_table, run_benchmark
    from zooctl.retrieval.index import index_asset
    from zooctl.store.bank import Bank

    monkeypatch.setenv("ZOOCTL_EMBEDDERS", "silhouette")
    bank = Bank(store)
    thin = tube_asset(bones=3, name="thin")
    twin = tube_asset(bones=3, radius=0.12, name="twin")
    fat = tube_asset(bones=2, bone_length=0.5, radius=0.6, name="fat")
    for a, plan in ((thin, "snake"), (twin, "snake"), (fat, "fish")):
        a.meta["body_plan"] = plan
        bank.add(a)
        index_asset(bank, a, ["silhouette"], n_views=3, size=48)
    make_video(thin, tmp_path / "v", frames=3, size=32, seed=0)
    res = run_benchmark(tmp_path / "v", store, overrides=TINY)
    (row,) = res["rows"]
    plan = row["plan"]
    assert row["template"] in ("twin", "fat")  # the video's own asset is left out
    assert plan["video"] == "snake" and plan["answerable"]
    assert plan["right"] == (row["template"] == "twin") and plan["tried_right"]  # both were tried
    counts = res["summary"]["full"]["plan"]
    assert counts == {
        "labelled": 1,
        "answerable": 1,
        "top1": int(plan["top1_right"]),
        "tried": 1,
        "template": int(plan["right"]),
    }
    table = markdown_table(res)
    assert "Right body plan (full): " in table and "of 1 labelled videos (1 with another" in table
    assert ("(right plan)" if plan["right"] else "(other plan)") in table
    own = run_benchmark(tmp_path / "v", store, own_template=True, overrides=TINY)
    assert "plan" not in own["rows"][0] and "plan" not in own["summary"]["full"]
    # the summary by the video's body plan, with or without retrieval
    assert json.loads(next((tmp_path / "v").glob("*/meta.json")).read_text())["body_plan"] == "snake"
    assert row["video_plan"] == "snake" and own["rows"][0]["video_plan"] == "snake"
    assert res["summary"]["full"]["by_plan"] == {
        "snake": {
            "videos": 1,
            "mask_iou": row["mask_iou"],
            "novel_view_iou": row["novel_view_iou"],
            "miou": row["miou"],
            "template_right": int(plan["right"]),
        }
    }
    assert "template_right" not in own["summary"]["full"]["by_plan"]["snake"]
    assert "By the video's body plan (full):" in table and "| snake | 1 | " in table
    assert f"| {int(plan['right'])} of 1 |" in table
    # a held-out animal (its asset not in the bank): the plan its video recorded
    ghost = tube_asset(bones=2, name="ghost")
    ghost.meta["body_plan"] = "fish"
    make_video(ghost, tmp_path / "h", frames=3, size=32, seed=0)
    held = run_benchmark(tmp_path / "h", store, overrides=TINY)
    (hrow,) = held["rows"]
    assert hrow["video_plan"] == "fish" and hrow["plan"]["video"] == "fish" and hrow["plan"]["answerable"]
    assert held["summary"]["full"]["plan"]["labelled"] == 1


def test_kept_trials_are_those_within_the_margin_of_the_best_score():
    from zooctl.fit.template import TRIAL_SEMANTIC_WEIGHT, kept_trials, trial_score

    assert kept_trials([0.80, 0.83, 0.70], 0.05) == [0, 1]
    assert kept_trials([0.80, 0.83, 0.70], 0.0) == [1]
    assert kept_trials([0.80, 0.83, 0.70], 0.2) == [0, 1, 2]
    # the semantic term counts as in pick_trial: a sure classifier keeps a lower trial IoU in
    sure = [trial_score(0.80, 1.0), trial_score(0.83, 0.0)]
    assert kept_trials(sure, 0.0) == [0] and TRIAL_SEMANTIC_WEIGHT > 0.03


def _trial_cfg(**trials):
    return FitConfig.from_dict(
        {**json.loads(json.dumps(TINY)), "trials": {"candidates": 2, "iters": 2, **trials}}
    )


def test_trials_stopped_at_a_checkpoint_and_resumed_are_the_full_trials(tmp_path, store):
    """With ``prune_at`` and no trial pruned, every trial pauses at the checkpoint and goes on from
    there: the same trial IoUs, winner and state as trials run in one go, and the same full fit."""
    import torch

    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.run import fit_video
    from zooctl.fit.template import try_candidates

    bank, thin = _bank_with_views(store)
    video = load_fit_video(make_video(thin, tmp_path / "v", frames=3, size=32, seed=0))
    runs = []
    for cfg in (_trial_cfg(), _trial_cfg(prune_at=1, prune_margin=0.99)):
        cands = [{"name": "fat", "score": -2.0}, {"name": "thin", "score": -1.0}]
        asset, out, state = try_candidates(bank, video, cands, cfg)
        runs.append((asset.name, out, state, fit_video(video, asset, cfg, resume=state)))
    (name_a, out_a, state_a, fit_a), (name_b, out_b, state_b, fit_b) = runs
    assert name_a == name_b == "thin"
    assert [c["trial_iou"] for c in out_a] == [c["trial_iou"] for c in out_b]
    assert not any("pruned_at" in c for c in out_b)
    assert state_b["iteration"] == state_a["iteration"] == 2
    assert state_b["history"] == state_a["history"]
    assert all(torch.equal(state_a["scene"][k], state_b["scene"][k]) for k in state_a["scene"])
    assert fit_a.history == fit_b.history and fit_a.camera_init == fit_b.camera_init
    a, b = fit_a.scene.state_dict(), fit_b.scene.state_dict()
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_a_clearly_worse_trial_stops_at_the_checkpoint(tmp_path, store, monkeypatch):
    """A trial behind the best by more than ``prune_margin`` at ``prune_at`` runs no further; the
    winner's trial goes on to ``trials.iters``, and the record says where the other stopped."""
    import zooctl.fit.view_trial as view_trial
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.template import try_candidates

    bank, thin = _bank_with_views(store)
    video = load_fit_video(make_video(thin, tmp_path / "v", frames=3, size=32, seed=0))
    continued = []
    real = view_trial.continue_trial
    monkeypatch.setattr(
        view_trial, "continue_trial", lambda v, a, *rest: continued.append(a.name) or real(v, a, *rest)
    )
    cands = [{"name": "fat", "score": -2.0}, {"name": "thin", "score": -1.0}]
    asset, out, state = try_candidates(bank, video, cands, _trial_cfg(prune_at=1, prune_margin=0.0))
    assert asset.name == "thin" and continued == ["thin"]
    assert out[0]["pruned_at"] == 1 and "pruned_at" not in out[1]
    assert out[1]["trial_iou"] > out[0]["trial_iou"]
    assert state["iteration"] == 2 and len(state["history"]["stage2"]) == 2


def test_a_trial_stopped_at_the_checkpoint_is_no_close_call():
    cands = [{"name": "a", "trial_iou": 0.80}, {"name": "b", "trial_iou": 0.795, "pruned_at": 0}]
    assert close_trials_note(cands, "a", "v") is None  # b's IoU is of fewer iterations
    del cands[1]["pruned_at"]
    assert close_trials_note(cands, "a", "v") is not None


def test_a_template_that_bulges_to_fit_loses_a_near_tie():
    """The trials' score takes off what a template's surface had to move: of two templates with
    about the same silhouette fit, the one whose displacement field moved further loses; a clearly
    better silhouette, or a classifier sure of the animal, still wins over it."""
    from zooctl.fit.template import pick_trial, trial_score

    assert trial_score(0.8, 0.0, 0.0) == 0.8
    # a dog template for a puffer fish against a fish's, the silhouettes fitted alike
    assert pick_trial([0.884, 0.883]) == 0
    assert pick_trial([trial_score(0.884, 0.0, 0.043), trial_score(0.883, 0.0, 0.014)]) == 1
    assert pick_trial([trial_score(0.880, 0.0, 0.020), trial_score(0.801, 0.0, 0.010)]) == 0
    # a swan: the long-legged bird the classifier is sure of bulges more than an anglerfish, and stays
    assert pick_trial([trial_score(0.913, 0.875, 0.082), trial_score(0.888, 0.001, 0.026)]) == 0
    assert abs(trial_score(0.8, 0.5, 0.01) - (0.8 + 0.05 - 0.015)) < 1e-12


def test_the_winner_is_tried_longer_and_kept_longer_only_where_that_fits_better(tmp_path, store):
    """``trials.longer``: a template shorter than the animal fits its video better made longer, and
    the fit goes on from that trial, its bones as long as the trial left them; the animal's own
    template made longer fits worse and stays as it is."""
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.run import fit_video
    from zooctl.fit.template import try_candidates

    bank, thin = _bank_with_views(store)
    tiny = json.loads(json.dumps(TINY))
    # Two trial iterations cannot turn a start, so this toy's own template needs each frame's own
    # box to start ahead of its longer copy (fits of ordinary length gain from the held distance).
    tiny["camera"]["depth"] = "box"
    cfg = FitConfig.from_dict({**tiny, "trials": {"candidates": 2, "iters": 2, "longer": 1.5}})
    long = tube_asset(bones=3, bone_length=1.5, name="long")
    for animal, kept in ((long, True), (thin, False)):
        video = load_fit_video(make_video(animal, tmp_path / animal.name, frames=3, size=32, seed=0))
        cands = [{"name": "thin", "score": -1.0}, {"name": "fat", "score": -2.0}]
        asset, out, state = try_candidates(bank, video, cands, cfg)
        assert asset.name == "thin" and 0 <= out[0]["longer_trial_iou"] <= 1
        assert ("length" in out[0]) is kept, (animal.name, out[0])
        assert "longer_trial_iou" not in out[1]  # only the winner is tried longer
        assert (out[0]["longer_trial_iou"] > out[0]["trial_iou"]) is kept
        res = fit_video(video, asset, cfg, resume=state)
        along = float(res.scene.model.bone_scales().detach()[0])
        assert (along > 1.3) is kept and along > 0.8


def test_trials_at_their_own_depth_hand_on_the_winners_trial_run_again_at_the_fits(tmp_path, store):
    """``trials.depth``: the candidates are compared from each frame's own box distance, and the
    winner's fit goes on from its trial run again from the fit's ``camera.depth``: the same trial
    IoUs as trials wholly at ``box``, the same state as the winner's trial wholly at ``held``."""
    from zooctl.fit.inputs import load_fit_video

    bank, thin = _bank_with_views(store)
    video = load_fit_video(make_video(thin, tmp_path / "v", frames=3, size=32, seed=0))

    def tried(camera_depth: str, trials_depth: str | None):
        _, asset, out, state = _fat_then_thin(
            bank, video, camera={"depth": camera_depth}, trials={"depth": trials_depth, "workers": 1}
        )
        return asset.name, out, state

    name, split, state = tried("held", "box")
    box_name, box, box_state = tried("box", None)
    held_name, held, held_state = tried("held", None)
    assert name == box_name == held_name == "thin"
    assert [c["trial_iou"] for c in split] == [c["trial_iou"] for c in box]
    assert split[1]["refit_trial_iou"] == held[1]["trial_iou"] and "refit_trial_iou" not in split[0]
    assert state["history"]["stage2"] == held_state["history"]["stage2"]
    assert state["history"]["stage2"] != box_state["history"]["stage2"]  # the start differs
    # the winner's camera search is its trial's, placed at the held distance, not made again
    assert state["camera_init"]["search_reused_from_depth"] == "box"
    assert "search_reused_from_depth" not in held_state["camera_init"]


def test_a_trials_body_turn_in_the_world_is_measured_against_the_cameras_turn():
    """`trial_world_spread`: a body that keeps its orientation in the world while the camera
    orbits (its root turning with the camera) spreads by nothing; one that also spins in the
    world by about its mean turn from the middle; without a turn, nothing is measured. The trial
    score takes the spread off at `TRIAL_WORLD_SPREAD_WEIGHT` a degree."""
    import torch

    from zooctl.fit.camera_init import camera_follow
    from zooctl.fit.template import TRIAL_WORLD_SPREAD_WEIGHT, trial_score
    from zooctl.fit.view_trial import trial_world_spread
    from zooctl.geometry import matrix_to_quat, quat_to_matrix

    def about_y(deg):  # (T, 3, 3) rotations about the vertical
        a = np.radians(deg)
        R = np.zeros((len(a), 3, 3))
        R[:, 0, 0], R[:, 0, 2], R[:, 1, 1], R[:, 2, 0], R[:, 2, 2] = (
            np.cos(a),
            np.sin(a),
            1,
            -np.sin(a),
            np.cos(a),
        )
        return R

    T = 21
    cams = about_y(4.0 * np.arange(T))  # the camera orbits 80 degrees
    turn = camera_follow(cams @ np.diag([1.0, -1.0, -1.0]), 0)
    start = quat_to_matrix(np.array([0.8, 0.2, 0.5, -0.1]) / np.linalg.norm([0.8, 0.2, 0.5, -0.1]))

    def state(R):
        return {"scene": {"root_rotation": torch.as_tensor(matrix_to_quat(R), dtype=torch.float32)}}

    still = turn @ start
    assert trial_world_spread(state(still), turn) < 0.1
    spin = about_y(2.0 * np.arange(T))  # the body spins 40 degrees about its up axis
    spinning = trial_world_spread(state(turn @ start @ spin), turn)
    assert 9.0 < spinning < 11.0  # 0..20 degrees either side of the middle: a mean of 10
    assert trial_world_spread(state(still), None) is None
    assert trial_world_spread(None, turn) is None
    assert trial_score(0.8, 0.0, 0.0, spinning) == pytest.approx(0.8 - TRIAL_WORLD_SPREAD_WEIGHT * spinning)
    assert trial_score(0.8, 0.0, 0.0, None) == 0.8


def test_the_trials_measure_the_body_turn_only_where_the_camera_turns(tmp_path, store):
    """Over a scene fixed in the world, seen by the benchmark's orbiting camera, every trial
    records how far its body turned in the world (``trial_world_spread_deg``); over a still
    background (a camera at rest to the read) no trial does, and ``camera.motion`` none reads
    nothing. Where the turn is read, each candidate is tried from two starts (``trials.carried``,
    the default) or, with it off, from the search's alone."""
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.template import trial_score, try_candidates

    bank, thin = _bank_with_views(store)
    kw = {"frames": 19, "size": 160, "seed": 1, "appearance": "textured"}
    world = load_fit_video(make_video(thin, tmp_path / "w", background="world", **kw))
    still = load_fit_video(make_video(thin, tmp_path / "s", **kw))
    assert FitConfig().trials.carried  # the default
    for video, motion, measured, carried in (
        (world, "given", True, True),
        (world, "given", True, False),
        (still, "given", False, True),
        (world, "none", False, True),
    ):
        cfg = FitConfig.from_dict(
            {
                **json.loads(json.dumps(TINY)),
                "camera": TINY["camera"] | {"motion": motion},
                "trials": TINY["trials"] | {"carried": carried, "carried_at": 1},
            }
        )
        cands = [
            {"name": "fat", "score": -2.0, "semantic": 0.0},
            {"name": "thin", "score": -1.0, "semantic": 0.0},
        ]
        _, out, state = try_candidates(bank, video, cands, cfg)
        # Two starts are compared at carried_at, and the better goes on to the trials' end.
        assert state["iteration"] == cfg.trials.iters == 2 and not any("pruned_at" in c for c in out)
        spreads = [c.get("trial_world_spread_deg") for c in out]
        assert all((s is not None) == measured for s in spreads), (motion, spreads)
        # Where the turn is read, each candidate is also tried from a start carried by it, and
        # keeps the start that scores better: its record says which, and the other's score.
        starts = [c.get("trial_start") for c in out]
        assert all((s in ("search", "carried")) == (measured and carried) for s in starts), (motion, starts)
        if measured:
            assert all(0.0 <= s < 180.0 for s in spreads)
        if measured and carried:
            for c in out:
                kept = trial_score(
                    c["trial_iou"], c["semantic"], c["trial_displacement"], c["trial_world_spread_deg"]
                )
                assert kept >= c["other_start_score"] - 1e-3


def test_the_fit_goes_on_carried_where_its_trial_started_carried():
    """`winner_config`: a chosen template whose trial started carried by the camera's turn goes
    on with ``camera.motion`` background (a long clip's later windows carried as its first);
    otherwise the config is the one given."""
    from zooctl.fit.template import winner_config

    cfg = FitConfig()
    cands = [{"name": "a", "trial_start": "carried"}, {"name": "b", "trial_start": "search"}, {"name": "c"}]
    assert winner_config(cfg, cands, "a").camera.motion == "background"
    assert cfg.camera.motion == "given"  # a copy
    assert winner_config(cfg, cands, "b") is cfg and winner_config(cfg, cands, "c") is cfg


def test_a_retrieval_sure_of_its_first_candidate_skips_the_trials(tmp_path, store, monkeypatch):
    """``trials.sure``: a first candidate ahead of every other by that much is fitted without
    trials; a lead short of it by a hair leaves the trials to choose. The lead is recorded."""
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.template import retrieval_lead, select_template

    monkeypatch.setenv("ZOOCTL_EMBEDDERS", "silhouette")
    bank, thin = _bank_with_views(store)
    video = load_fit_video(make_video(thin, tmp_path / "v", frames=3, size=32, seed=0))

    def select(sure):
        cfg = FitConfig.from_dict(
            {**json.loads(json.dumps(TINY)), "trials": {"candidates": 2, "iters": 2, "sure": sure}}
        )
        return select_template(bank, None, video, cfg)

    asset, cands, state, seconds = select(None)
    lead = cands[0]["lead"]
    assert lead == pytest.approx(retrieval_lead(cands), abs=1e-4) and lead >= 0
    assert lead == pytest.approx(cands[1]["score"] - cands[0]["score"], abs=1e-4)  # two assets: the other one
    assert all("trial_iou" in c for c in cands) and state is not None and seconds > 0
    # a first candidate behind another (the family's best moved first) leads by a negative amount
    assert retrieval_lead([{"score": -1.0}, {"score": -2.5}, {"score": -0.5}]) == pytest.approx(-1.5)
    asset, cands, state, seconds = select(lead)
    assert asset.name == cands[0]["name"] and state is None and seconds is None
    assert not any("trial_iou" in c for c in cands)
    asset, cands, state, seconds = select(lead + 0.01)
    assert all("trial_iou" in c for c in cands) and state is not None
    from zooctl.errors import UsageError

    with pytest.raises(UsageError, match="trials.sure"):
        FitConfig.from_dict({"trials": {"sure": -1.0}})


def test_a_trials_body_seen_from_the_videos_other_views(tmp_path):
    """`trial_view_consistency`: two fits that match every frame's mask exactly, one whose body
    holds still in the world while the camera orbits, one whose body turns with the camera (so
    it spins in the world): the first, posed at one frame and turned by the camera's turn, covers
    the other frames' masks exactly; the second does not. Without a turn, nothing is measured."""
    import torch

    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.run import fit_video
    from zooctl.fit.view_trial import trial_view_consistency
    from zooctl.geometry import matrix_to_quat, quat_to_matrix
    from zooctl.render.raster import rasterize

    def about(axis, deg):  # (T, 3, 3) rotations about a unit axis (Rodrigues)
        k = np.asarray(axis, float) / np.linalg.norm(axis)
        K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        a = np.radians(np.asarray(deg, float))[:, None, None]
        return np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * (K @ K)

    asset = tube_asset(bones=3)
    video = load_fit_video(make_video(asset, tmp_path / "v", frames=9, size=48, seed=0))
    cfg = FitConfig.from_dict({**json.loads(json.dumps(TINY)), "ablation": {"optimise": False}})
    res = fit_video(video, asset, cfg)
    T = res.scene.num_frames
    turn = about([0.3, 1.0, 0.2], 10.0 * np.arange(T))  # the camera orbits 80 degrees
    start = quat_to_matrix(res.scene.root_rotation[0].detach().numpy().astype(np.float64))

    def posed(R):  # the scene's roots set to R (T, 3, 3), the masks made its own silhouettes
        with torch.no_grad():
            res.scene.root_rotation.copy_(torch.as_tensor(matrix_to_quat(R), dtype=torch.float32))
            res.scene.root_translation.copy_(res.scene.root_translation[:1].expand(T, -1).clone())
            v = res.scene.pose().vertices
            cam = res.input_camera()
            res.video.masks = rasterize(v, res.scene.faces, cam.expand(T)).mask.numpy()
        return res

    still = trial_view_consistency(posed(turn @ start), turn, sources=3, step=1)
    spinning = trial_view_consistency(posed(np.repeat(start[None], T, 0)), turn, sources=3, step=1)
    assert still > 0.98
    assert spinning < still - 0.1
    assert trial_view_consistency(res, None) is None


def test_the_trials_score_a_bodys_other_views_where_asked(tmp_path, store):
    """``trials.view_consistency``: where the camera turns round the animal, every candidate's
    record gets its `trial_view_consistency` and the score adds the weight times it; at 0 (the
    default) nothing is measured."""
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.template import trial_score, try_candidates

    bank, thin = _bank_with_views(store)
    video = load_fit_video(make_video(thin, tmp_path / "v", frames=6, size=32, seed=0))
    a = np.radians(10.0 * np.arange(6))  # the camera orbits 50 degrees about the vertical
    orbit = np.zeros((6, 3, 3))
    orbit[:, 0, 0], orbit[:, 0, 2], orbit[:, 1, 1], orbit[:, 2, 0], orbit[:, 2, 2] = (
        np.cos(a),
        np.sin(a),
        1,
        -np.sin(a),
        np.cos(a),
    )
    video.camera_rotations = np.asarray(video.gt["cam_rotation"][0]) @ orbit
    for weight in (0.0, 0.5):
        cfg = FitConfig.from_dict(
            {
                **json.loads(json.dumps(TINY)),
                "trials": {"candidates": 2, "iters": 2, "view_consistency": weight},
            }
        )
        cands = [{"name": "fat", "score": -2.0}, {"name": "thin", "score": -1.0}]
        _, out, _ = try_candidates(bank, video, cands, cfg)
        for c in out:
            assert ("trial_view_consistency" in c) is (weight > 0)
            if weight > 0:
                assert 0.0 <= c["trial_view_consistency"] <= 1.0
    assert trial_score(0.8, 0.0, 0.0, None, 0.5, 0.2) == pytest.approx(0.9)
    assert trial_score(0.8, 0.0, 0.0, None, None, 0.2) == pytest.approx(0.8)
