"""Template trials: retrieval's best candidates each get a short fit and the best-fitting one wins."""

from __future__ import annotations

import json

import numpy as np
from test_fit_e2e import validate_record

from zooctl.benchdata.make import make_video
from zooctl.fit.config import FitConfig
from zooctl.rig.synthetic import tube_asset

TINY = {
    "fit_size": 32,
    "stage1": {"iters": 4, "batch": 4},
    "stage2": {"iters": 3, "batch": 3},
    "camera": {"azimuths": 4, "elevations": [10.0], "search_size": 32},
    "trials": {"candidates": 2, "iters": 6},
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


def test_trials_pick_the_template_whose_fit_matches_best(tmp_path, store):
    """Handed the wrong template first, the trial fits still choose the animal of the video."""
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.template import try_candidates

    bank, thin = _bank_with_views(store)
    video = load_fit_video(make_video(thin, tmp_path / "v", frames=3, size=32, seed=0))
    cfg = FitConfig.from_dict(json.loads(json.dumps(TINY)))
    cands = [{"name": "fat", "score": -2.0}, {"name": "thin", "score": -1.0}]
    asset, out = try_candidates(bank, video, cands, cfg)
    assert asset.name == "thin"
    assert out[1]["trial_iou"] > out[0]["trial_iou"] and 0 <= out[0]["trial_iou"] <= 1
    assert cfg.stage2.iters == 3 and cfg.trials.candidates == 2  # the caller's config is untouched
    one = FitConfig.from_dict({**json.loads(json.dumps(TINY)), "trials": {"candidates": 1}})
    fresh = [{"name": "fat", "score": -2.0}, {"name": "thin", "score": -1.0}]
    asset, out = try_candidates(bank, video, fresh, one)
    assert asset.name == "fat" and "trial_iou" not in out[0]  # one candidate: no trial fits


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
    validate_record(json.loads(open(rec["outputs"]["fit_json"]).read()))  # the file the fit writes
    assert np.isfinite(rec["metrics"]["mask_iou"])
