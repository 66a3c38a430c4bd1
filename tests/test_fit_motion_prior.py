"""The fit's ``motion`` pose prior: a motion VAE scores windows of the fitted rotations (issue 20)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from zooctl.motion.model import MotionConfig
from zooctl.motion.prior import PonymationPrior

SMALL = dict(arch="trajectory", width=16, layers=1, heads=4, latent=8, length=8, z_tokens=1)
TINY = {
    "fit_size": 32,
    "stage1": {"iters": 3, "batch": 4},
    "stage2": {"iters": 3, "batch": 3},
    "camera": {"azimuths": 4, "elevations": [10.0], "search_size": 32},
    "trials": {"candidates": 1},
    "weights": {"pose_prior": 0.1},
}


@pytest.fixture(scope="module")
def quad():
    from zooctl.procedural import build_animal

    return build_animal("quadruped")


def _rest(asset, T: int) -> torch.Tensor:
    _, q, _ = asset.rest_trs()
    return torch.as_tensor(np.tile(np.asarray(q), (T, 1, 1)), dtype=torch.float32)


def test_the_prior_reads_rotations_relative_to_the_rest_pose(quad):
    """An untrained VAE decodes the rest pose, so the template standing still in its rest pose
    reconstructs exactly while a clip's motion does not; the gradient reaches the fitted
    rotations of the window, never the VAE's weights."""
    prior = PonymationPrior(MotionConfig(**SMALL))
    sp = prior.sequence_prior(quad, 30.0)
    frames = torch.arange(4, 12)
    still = sp.terms(_rest(quad, 20), frames)
    assert float(still["rotation"]) < 1e-10 and float(still["joints"]) < 1e-10
    clip = next(iter(quad.clips.values()))
    moving = torch.as_tensor(np.asarray(clip.rotations[:20]), dtype=torch.float32).requires_grad_()
    terms = sp.terms(moving, frames)
    assert float(terms["rotation"].detach()) > 1e-4
    assert float(terms["total"].detach()) > float(still["total"])
    terms["total"].backward()
    touched = moving.grad.abs().sum((1, 2)) > 0
    assert touched[sp.window(frames, 20)].all() and not touched[12:].any()
    assert all(p.grad is None for p in prior.model.parameters())


def test_the_window_follows_the_step_and_the_frame_rates(quad):
    sp = PonymationPrior(MotionConfig(**SMALL)).sequence_prior(quad, 60.0)  # prior at 30 fps
    assert sp.span == 15
    assert sp.window(torch.arange(0, 8), 100).tolist() == list(range(0, 16, 2))
    assert sp.window(torch.arange(90, 98), 100).tolist() == list(range(85, 100, 2))
    assert sp.window(torch.arange(40, 48), 100).tolist() == list(range(36, 51, 2))  # centred
    assert sp.window(torch.arange(0, 4), 10).tolist() == [0, 2, 4, 6, 8, 9, 9, 9]  # short video


def _store_with_tube_video(store, tmp_path):
    from zooctl.benchdata.make import make_video
    from zooctl.rig.synthetic import tube_asset
    from zooctl.store.bank import Bank

    tube = tube_asset(bones=3, name="tube")
    Bank(store).add(tube)
    return make_video(tube, tmp_path / "v", frames=4, size=32, seed=0)


def test_a_fit_with_the_motion_prior_records_which_prior(tmp_path, store):
    from zooctl.fit.config import FitConfig
    from zooctl.fit.job import fit_job
    from zooctl.store.motion_store import MotionStore

    folder = _store_with_tube_video(store, tmp_path)
    prior = PonymationPrior(MotionConfig(**SMALL))
    MotionStore.open(store).add("tiny", lambda d: prior.save(d, "tiny"))
    cfg = FitConfig.from_dict({**json.loads(json.dumps(TINY)), "pose_prior": {"kind": "motion"}})
    rec = fit_job(str(folder), store, cfg, name="m", template="tube", outputs=("loss",))
    assert rec["config"]["pose_prior"]["motion"] == str(MotionStore.open(store).path("tiny").resolve())
    last = rec["losses"]["stage2"]["last"]
    assert last["pose"] > 0 and np.isfinite(last["total"])
    assert cfg.pose_prior.motion is None  # the caller's config is untouched


def test_the_motion_prior_needs_a_prior_that_scores_motion(tmp_path, store):
    from zooctl.errors import NotFoundError, UsageError
    from zooctl.fit.config import FitConfig
    from zooctl.fit.job import fit_job
    from zooctl.motion.dataset import sequences_from_asset
    from zooctl.motion.pca_prior import PCAPrior
    from zooctl.procedural import build_animal
    from zooctl.store.motion_store import MotionStore

    folder = _store_with_tube_video(store, tmp_path)
    cfg = FitConfig.from_dict({**json.loads(json.dumps(TINY)), "pose_prior": {"kind": "motion"}})
    with pytest.raises(NotFoundError, match="no motion prior in the store"):
        fit_job(str(folder), store, cfg, name="m", template="tube", outputs=())
    pca = PCAPrior(length=8, components=2)
    pca.fit(sequences_from_asset(build_animal("quadruped")))
    MotionStore.open(store).add("pca", lambda d: pca.save(d, "pca"))
    with pytest.raises(UsageError, match="cannot score a fitted motion"):
        fit_job(str(folder), store, cfg, name="m", template="tube", outputs=())
