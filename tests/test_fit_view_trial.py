"""The depth-mirror trial: a start that sees the animal from below is tried against its mirror."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree

from zooctl.benchdata.make import make_video
from zooctl.errors import UsageError
from zooctl.fit.camera_init import CameraInit, view_rotation
from zooctl.fit.config import FitConfig
from zooctl.fit.depth_mirror import depth_mirror, view_elevation
from zooctl.fit.view_trial import trial_with_mirror
from zooctl.geometry import matrix_to_quat, quat_to_matrix
from zooctl.rig.synthetic import tube_asset

TINY = {
    "fit_size": 32,
    "stage1": {"iters": 4, "batch": 4},
    "stage2": {"iters": 4, "batch": 3},
    "camera": {"azimuths": 4, "elevations": [-30.0], "search_size": 32},
    "trials": {"iters": 2},
}


def _config(**camera) -> FitConfig:
    data = json.loads(json.dumps(TINY))
    data["camera"].update(camera)
    return FitConfig.from_dict(data)


def test_depth_mirror_reflects_every_frame_through_the_animals_centre():
    rng = np.random.default_rng(0)
    half = rng.normal(size=(50, 3)) + [1.0, 0.0, 0.0]
    plane_x = 0.2  # the template's mirror plane x = 0.2, off the origin
    rest = np.concatenate([half, half * [-1, 1, 1] + [2 * plane_x, 0, 0]])
    rots = np.stack([view_rotation(a, e, r) for a, e, r in ((30, 20, 0), (-100, -35, 5), (170, 5, -10))])
    trans = np.array([[0.1, -0.2, -5.0], [0.3, 0.0, -7.0], [-0.4, 0.2, -6.0]])
    init = CameraInit(100.0, np.stack([matrix_to_quat(r) for r in rots]), trans, [], 0.5, [0.5])
    mirror = depth_mirror(init, rest, np.array([1.0, 0.0, 0.0]), plane_x)
    R2 = quat_to_matrix(mirror.root_rotation)
    assert np.allclose(np.linalg.det(R2), 1.0)  # a rotation, not a reflection
    for t in range(3):
        posed = rest @ rots[t].T + trans[t]
        centre_z = posed.mean(0)[2]
        expected = posed * [1, 1, -1] + [0, 0, 2 * centre_z]  # mirrored in depth about its centre
        got = rest @ R2[t].T + mirror.root_translation[t]
        assert cKDTree(expected).query(got)[0].max() < 1e-9
    # The mirror of a view from above is a view from below (a vertical mirror plane).
    assert view_elevation(init.root_rotation[:1]) == pytest.approx(20.0)
    assert view_elevation(mirror.root_rotation[:1]) == pytest.approx(-20.0)
    assert mirror.focal == init.focal and mirror.iou == init.iou


def test_a_start_from_below_is_tried_against_its_mirror_and_the_fit_goes_on_from_the_one_kept(tmp_path):
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.run import fit_video

    thin = tube_asset(bones=3, name="thin")
    video = load_fit_video(make_video(thin, tmp_path / "v", frames=3, size=32, seed=0))
    cfg = _config()
    trial = trial_with_mirror(video, thin, cfg)
    iou, state, info = trial.iou, trial.state, trial.view
    assert trial.displacement > 0  # the displacement field moved the surface in the trial
    assert info["elevation_deg"] < 0  # the only elevation searched looks up at the animal
    both = info["trial_iou"]
    kept = "mirror" if both["mirror"] >= both["search"] - cfg.camera.mirror_margin else "search"
    assert info["start"] == kept and iou == pytest.approx(both[kept], abs=1e-4)
    assert info["extra_seconds"] > 0
    assert state["iteration"] == 2 and state["camera_init"]["view_trial"] == info
    again = fit_video(video, thin, cfg, resume=state)
    assert len(again.history["stage2"]) == cfg.stage2.iters
    assert again.camera_init["view_trial"]["start"] == kept
    # A margin of 0.99 keeps the mirror whatever its IoU; no mirror trial when it is switched off.
    info = trial_with_mirror(video, thin, _config(mirror_margin=0.99)).view
    assert info["start"] == "mirror"
    info = trial_with_mirror(video, thin, cfg, mirror=False).view
    assert info["start"] == "search" and "trial_iou" not in info
    with pytest.raises(UsageError, match="mirror_trial"):
        _config(mirror_trial="sometimes")


def test_a_search_made_at_one_distance_rule_starts_a_fit_at_another_as_its_own_search_would(tmp_path):
    """`fit_video`'s ``found``: a paused fit's camera search, placed at another ``camera.depth``
    (`placed_at_depth`), gives the fit that searched for itself, to the bit, through a
    checkpoint's tensors too; the mirror start reuses its own fit's search; a search made for
    another body or other camera settings, or placed at a rule that cannot give the asked one, is
    searched again."""
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.run import fit_video
    from zooctl.store.fits import _plain

    thin = tube_asset(bones=3, name="thin")
    video = load_fit_video(make_video(thin, tmp_path / "v", frames=4, size=32, seed=1))
    box, held = _config(depth="box"), _config(depth="held")

    def same(a, b) -> bool:
        sa, sb = a.scene.state_dict(), b.scene.state_dict()
        return a.history == b.history and all(np.array_equal(sa[k], sb[k]) for k in sa)

    at_box = fit_video(video, thin, box, pause_at=2)
    found = at_box.paused["search"]
    assert found["depth"] == "box" and "search_reused_from_depth" not in at_box.camera_init
    own = fit_video(video, thin, held)
    buf = io.BytesIO()
    torch.save(_plain(found), buf)  # as the fits store writes a checkpoint and reads it back
    stored = torch.load(io.BytesIO(buf.getvalue()), weights_only=True)
    for handed in (found, stored):
        reused = fit_video(video, thin, held, found=handed)
        assert reused.camera_init["search_reused_from_depth"] == "box"
        assert same(reused, own)
    assert not np.array_equal(own.scene.root_translation.detach(), at_box.scene.root_translation.detach())
    mirror = fit_video(video, thin, box, start="mirror")
    assert same(fit_video(video, thin, box, start="mirror", found=found), mirror)
    from_held = fit_video(video, thin, held, pause_at=2).paused["search"]
    for cfg, length, hand in (
        (box, 1.0, from_held),
        (held, 1.3, found),
        (_config(depth="held", azimuths=8), 1.0, found),
    ):
        res = fit_video(video, thin, cfg, found=hand, length=length)
        assert "search_reused_from_depth" not in res.camera_init


def test_a_start_from_above_is_not_mirrored_and_pausing_changes_nothing(tmp_path):
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.run import fit_video

    thin = tube_asset(bones=3, name="thin")
    video = load_fit_video(make_video(thin, tmp_path / "v", frames=3, size=32, seed=0))
    cfg = _config(elevations=[30.0])
    kept = trial_with_mirror(video, thin, cfg)
    state, info = kept.state, kept.view
    assert info["start"] == "search" and info["elevation_deg"] > 0 and "trial_iou" not in info
    resumed = fit_video(video, thin, cfg, resume=state)
    whole = fit_video(video, thin, cfg)
    np.testing.assert_allclose(resumed.iou, whole.iou, atol=1e-6)


def fit_named_tube(tmp_path, store, capsys, config: dict, frames: int = 3) -> dict:
    """`zooctl fit` of a tube's video with the tube named as its template: the checked record."""
    from cli_helpers import run_inprocess
    from test_fit_e2e import validate_record

    from zooctl.store.bank import Bank

    thin = tube_asset(bones=3, name="thin")
    Bank(store).add(thin)
    folder = make_video(thin, tmp_path / "v", frames=frames, size=32, seed=0)
    cfg = tmp_path / "c.json"
    cfg.write_text(json.dumps(config))
    r = run_inprocess(
        capsys, "fit", str(folder), "--template", "thin", "--config", str(cfg), "--name", "vt", "--json"
    )
    assert r.code == 0, r.err
    rec = json.loads((store / "fits" / "vt" / "record.json").read_text())
    validate_record(rec)
    return rec


def test_fit_with_a_given_template_records_the_mirror_trial(tmp_path, store, capsys):
    rec = fit_named_tube(tmp_path, store, capsys, TINY)
    view = rec["camera"]["search"]["view_trial"]
    assert view["start"] in ("search", "mirror") and set(view["trial_iou"]) == {"search", "mirror"}
    assert rec["timings"]["mirror_trial"] == view["extra_seconds"]
    assert rec["losses"]["stage2"]["steps"] == TINY["stage2"]["iters"]  # the trial's steps and the rest


def test_retrieved_candidates_are_mirrored_only_when_asked(tmp_path, store):
    """``camera.mirror_trial``: ``given`` (default) leaves retrieval's candidates alone, ``always``
    tries each one's depth mirror too."""
    from test_fit_trials import _bank_with_views

    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.template import try_candidates

    bank, thin = _bank_with_views(store)
    video = load_fit_video(make_video(thin, tmp_path / "v", frames=3, size=32, seed=0))
    for mode, tried in (("given", False), ("always", True)):
        cands = [{"name": "fat", "score": -2.0}, {"name": "thin", "score": -1.0}]
        cfg = FitConfig.from_dict({**json.loads(json.dumps(TINY)), "trials": {"candidates": 2, "iters": 2}})
        cfg.camera.mirror_trial = mode
        _, out, state = try_candidates(bank, video, cands, cfg)
        assert all(("trial_iou" in c["view_trial"]) == tried for c in out), mode
        assert state["camera_init"]["view_trial"]["elevation_deg"] < 0


def test_a_turned_start_faces_at_least_90_degrees_from_the_searchs(tmp_path):
    """``start="turned"``: the camera search's best view at least 90 degrees of azimuth from its
    pick, refined and tracked as the pick is; a fit goes on from it as from any start."""
    from zooctl.fit.camera_init import initialise_camera
    from zooctl.fit.config import CameraConfig
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.run import fit_video

    thin = tube_asset(bones=3, name="thin")
    video = load_fit_video(make_video(thin, tmp_path / "v", frames=3, size=32, seed=0))
    cfg = CameraConfig(azimuths=8, elevations=[10.0], search_size=32)
    search = initialise_camera(thin.vertices, thin.faces, video.masks, cfg, 1.0)
    turned = initialise_camera(thin.vertices, thin.faces, video.masks, cfg, 1.0, turned=True)
    gap = turned.candidates[0]["azimuth"] - search.candidates[0]["azimuth"]
    assert abs((gap + 180.0) % 360.0 - 180.0) >= 90.0
    assert all(
        abs((c["azimuth"] - search.candidates[0]["azimuth"] + 180) % 360 - 180) >= 90
        for c in turned.candidates
    )
    a = quat_to_matrix(np.asarray(search.root_rotation[0]))
    b = quat_to_matrix(np.asarray(turned.root_rotation[0]))
    assert np.degrees(np.arccos(np.clip((np.trace(a.T @ b) - 1) / 2, -1, 1))) > 45.0
    res = fit_video(video, thin, _config(elevations=[10.0]), start="turned")
    assert np.isfinite(res.iou).all()
    with pytest.raises(ValueError, match="search, mirror or turned"):
        fit_video(video, thin, _config(), start="sideways")


def test_where_the_camera_turns_the_mirror_trial_weighs_each_starts_turn_in_the_world(tmp_path):
    """Over a scene fixed in the world (the benchmark's orbiting camera), both starts record how far
    their body turned in the world, and the start kept is the one of higher IoU less
    `TRIAL_WORLD_SPREAD_WEIGHT` times that turn (within the margin); over a still background
    nothing is measured and the IoU alone decides, as before."""
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.view_trial import TRIAL_WORLD_SPREAD_WEIGHT

    thin = tube_asset(bones=3, name="thin")
    kw = {"frames": 19, "size": 160, "seed": 1, "appearance": "textured"}
    cfg = _config(motion="background")
    world = load_fit_video(make_video(thin, tmp_path / "w", background="world", **kw))
    info = trial_with_mirror(world, thin, cfg).view
    iou, spread = info["trial_iou"], info["world_spread_deg"]
    assert set(spread) == {"search", "mirror"} and all(0.0 <= s < 180.0 for s in spread.values())
    score = {k: iou[k] - TRIAL_WORLD_SPREAD_WEIGHT * spread[k] for k in iou}
    assert info["start"] == (
        "mirror" if score["mirror"] >= score["search"] - cfg.camera.mirror_margin else "search"
    )
    still = load_fit_video(make_video(thin, tmp_path / "s", **kw))
    info = trial_with_mirror(still, thin, cfg).view
    assert "world_spread_deg" not in info and set(info["trial_iou"]) == {"search", "mirror"}
    both = info["trial_iou"]
    assert info["start"] == (
        "mirror" if both["mirror"] >= both["search"] - cfg.camera.mirror_margin else "search"
    )
