"""The clips pose prior (`zooctl.fit.pose_prior`): learned from the template's clips, in the fit."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from fit_helpers import tiny_overrides

from zooctl.asset import Clip
from zooctl.errors import UsageError
from zooctl.fit.config import FitConfig
from zooctl.fit.losses import clip_pose_loss, joint_limit_loss
from zooctl.fit.pose_prior import clip_joint_limits, clip_pose_stats
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

    tiny = tiny_overrides(3) | {"pose_prior": {"kind": "clips"}}
    cfg = FitConfig.from_dict(json.loads(json.dumps(tiny)))
    assert cfg.to_dict()["pose_prior"] == {
        "kind": "clips",
        "min_std_deg": 10.0,
        "motion": None,
        "limit_margin_deg": 30.0,
    }
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


def test_joint_limits_cost_only_beyond_the_clips_range():
    """Limits from a clip that bends joint 1 about x from 0.2 to 0.8 rad, widened by 10 degrees:
    no cost inside (the clips' own poses, the rest pose of a joint the clips never move within
    the margin), a cost growing with the excess outside, and a gradient that turns back in."""
    asset = tube_asset(bones=3, name="tube")
    _, q, _ = asset.rest_trs()
    rest = torch.as_tensor(q, dtype=torch.float32)
    J = len(asset.parents)
    aa = torch.zeros(20, J, 3)
    aa[:, 1, 0] = torch.linspace(0.2, 0.8, 20)
    rots = quat_mul(rest[None].expand(20, J, 4), axis_angle_to_quat(aa))
    limits = clip_joint_limits(_with_clip(asset, rots.numpy()), margin_deg=10.0)
    m = np.radians(10.0)
    assert limits.frames == 20
    assert (
        abs(float(limits.low[1, 0]) - (0.2 - m)) < 1e-5 and abs(float(limits.high[1, 0]) - (0.8 + m)) < 1e-5
    )
    assert abs(float(limits.high[2, 1]) - m) < 1e-6  # a joint the clip never moves: rest +- margin

    def posed(joint, axis, angle):
        a = torch.zeros(1, J, 3)
        a[0, joint, axis] = angle
        return quat_mul(rest[None], axis_angle_to_quat(a))

    assert float(joint_limit_loss(rots, rest, limits)) == 0.0
    assert float(joint_limit_loss(posed(1, 0, 0.05), rest, limits)) == 0.0  # 0.05 > 0.2 - 10 deg
    small = float(joint_limit_loss(posed(1, 0, 1.3), rest, limits))
    large = float(joint_limit_loss(posed(1, 0, 1.6), rest, limits))
    assert abs(small - (1.3 - 0.8 - m) ** 2) < 1e-4 and large > small > 0
    assert float(joint_limit_loss(posed(2, 2, 0.5), rest, limits)) > 0  # bent where the clips never bend
    x = posed(1, 0, 1.3).requires_grad_(True)
    joint_limit_loss(x, rest, limits).backward()
    step = x.detach() - 0.1 * x.grad
    assert float(joint_limit_loss(step, rest, limits)) < small
    bare = tube_asset(bones=3, name="t2")
    bare.clips = {}
    assert clip_joint_limits(bare) is None  # nothing to learn a range from: no limits


def test_fit_uses_joint_limits_only_when_weighted(tmp_path):
    from zooctl.benchdata.make import make_video
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.run import fit_video

    tiny = tiny_overrides(3) | {"weights": {"joint_limits": 1.0}, "pose_prior": {"limit_margin_deg": 5.0}}
    cfg = FitConfig.from_dict(json.loads(json.dumps(tiny)))
    assert cfg.to_dict()["weights"]["joint_limits"] == 1.0 and cfg.pose_prior.limit_margin_deg == 5.0
    asset = tube_asset(bones=3, name="tube")
    assert asset.clips, "the synthetic tube has clips to learn limits from"
    video = load_fit_video(make_video(asset, tmp_path / "v", frames=4, size=32, seed=0))
    res = fit_video(video, asset, cfg)
    assert res.scene.joint_limits is not None and all("limits" in s for s in res.history["stage2"])
    off = fit_video(video, asset, FitConfig.from_dict({k: v for k, v in tiny.items() if k != "weights"}))
    assert off.scene.joint_limits is None and all("limits" not in s for s in off.history["stage2"])
    with pytest.raises(UsageError, match="limit_margin_deg"):
        FitConfig.from_dict({"pose_prior": {"limit_margin_deg": -1}})
    for bad in (-1.0, float("nan")):
        with pytest.raises(UsageError, match="weights.joint_limits"):
            FitConfig.from_dict({"weights": {"joint_limits": bad}})


def test_joint_limits_without_clips_say_so(tmp_path):
    from zooctl.benchdata.make import make_video
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.run import _Silent, fit_video

    class Said(_Silent):
        def __init__(self):
            self.lines = []

        def message(self, text):
            self.lines.append(text)

    asset = tube_asset(bones=3, name="bare")
    asset.clips = {}
    video = load_fit_video(make_video(asset, tmp_path / "v", frames=4, size=32, seed=0))
    said = Said()
    cfg = FitConfig.from_dict(tiny_overrides(2) | {"weights": {"joint_limits": 1.0}})
    res = fit_video(video, asset, cfg, said)
    assert res.scene.joint_limits is None and all("limits" not in s for s in res.history["stage2"])
    assert any("no clips to learn joint limits from" in line for line in said.lines), said.lines
