"""The clips pose prior (`zooctl.fit.pose_prior`): learned from the template's clips, in the fit."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from zooctl.asset import Clip
from zooctl.errors import UsageError
from zooctl.fit.config import FitConfig
from zooctl.fit.losses import clip_pose_loss
from zooctl.fit.pose_prior import clip_pose_stats
from zooctl.rig.rotations import axis_angle_to_quat, quat_mul
from zooctl.rig.synthetic import tube_asset


def _with_clip(asset, rots):
    T, J = rots.shape[:2]
    t, _, s = asset.rest_trs()
    asset.clips = {
        "wave": Clip(
            "wave", 30.0, rots, np.broadcast_to(t, (T, J, 3)).copy(), np.broadcast_to(s, (T, J, 3)).copy()
        )
    }
    return asset


def test_clip_statistics_prefer_the_clips_motion():
    """A joint the clips bend about x: bending it about x costs less than the same angle about z,
    and the stats' mean sits at the clips' mean bend."""
    asset = tube_asset(bones=3, name="tube")
    _, q, _ = asset.rest_trs()
    rest = torch.as_tensor(q, dtype=torch.float32)
    J = len(asset.parents)
    ang = torch.linspace(0.2, 0.8, 20)
    aa = torch.zeros(20, J, 3)
    aa[:, 1, 0] = ang
    rots = quat_mul(rest[None].expand(20, J, 4), axis_angle_to_quat(aa))
    stats = clip_pose_stats(_with_clip(asset, rots.numpy()), min_std_deg=5.0)
    assert stats.frames == 20 and abs(float(stats.mean[1, 0]) - 0.5) < 1e-3

    def cost(axis):
        a = torch.zeros(1, J, 3)
        a[0, 1, axis] = 0.5
        return float(clip_pose_loss(quat_mul(rest[None], axis_angle_to_quat(a)), rest, stats))

    assert cost(0) < 0.1 * cost(2)
    # Without clips: rest-pose statistics (mean 0, the floor as the deviation).
    bare = tube_asset(bones=3, name="t2")
    bare.clips = {}
    plain = clip_pose_stats(bare, min_std_deg=5.0)
    assert plain.frames == 0 and float(clip_pose_loss(rest[None], rest, plain)) == 0.0


def test_fit_records_and_uses_the_pose_prior(tmp_path):
    from zooctl.benchdata.make import make_video
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.run import fit_video

    tiny = {
        "fit_size": 32,
        "stage1": {"iters": 2, "batch": 4},
        "stage2": {"iters": 3, "batch": 3},
        "camera": {"azimuths": 4, "elevations": [10.0], "search_size": 32},
        "pose_prior": {"kind": "clips"},
    }
    cfg = FitConfig.from_dict(json.loads(json.dumps(tiny)))
    assert cfg.to_dict()["pose_prior"] == {"kind": "clips", "min_std_deg": 10.0, "motion": None}
    asset = tube_asset(bones=3, name="tube")
    video = load_fit_video(make_video(asset, tmp_path / "v", frames=4, size=32, seed=0))
    res = fit_video(video, asset, cfg)
    assert res.scene.clip_stats is not None and all("pose" in s for s in res.history["stage2"])
    none = fit_video(
        video, asset, FitConfig.from_dict(json.loads(json.dumps(tiny | {"pose_prior": {"kind": "none"}})))
    )
    assert all("pose" not in s for s in none.history["stage2"])
    with pytest.raises(UsageError, match="pose_prior"):
        FitConfig.from_dict({"pose_prior": {"kind": "vae"}})
