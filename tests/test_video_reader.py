"""A stored video read a few frames at a time (`zooctl.store.video_reader`), and the fit of a
stored video that never holds its frames and flow whole."""

from __future__ import annotations

import json
import pickle

import h5py
import numpy as np
import pytest
from video_helpers import synthetic_video

from zooctl.errors import StoreError
from zooctl.store.video_reader import StoredVideo
from zooctl.store.videos import VideoStore


def _stored(tmp_path, t: int = 20, h: int = 24, w: int = 32):
    rec = synthetic_video("clip", t=t, h=h, w=w)
    rec.occlusion_forward[:, :4] = True
    vs = VideoStore.open(tmp_path / "store")
    vs.add(rec)
    return vs, rec


def test_frame_arrays_read_what_they_are_indexed_with(tmp_path):
    vs, rec = _stored(tmp_path)
    with StoredVideo(vs.path("clip")) as sv:
        assert sv.num_frames == 20 and sv.frames.shape == (20, 24, 32, 3) and sv.fps == 30.0
        assert (sv.frames[3] == rec.frames[3]).all() and (sv.frames[-1] == rec.frames[-1]).all()
        assert (sv.frames[2:19] == rec.frames[2:19]).all()  # across chunk boundaries
        assert (sv.frames[np.array([5, 1, 5])] == rec.frames[[5, 1, 5]]).all()
        flow16 = rec.flow_forward.astype(np.float16).astype(np.float32)  # stored as float16
        part = sv.flow_forward[1:18, 2:10, 3:9]
        assert part.dtype == np.float32 and (part == flow16[1:18, 2:10, 3:9]).all()
        assert (sv.flow_valid[:] == ~rec.occlusion_forward).all()
        assert (sv.masks[:] == rec.masks).all() and sv.masks.head(5)[:].shape == (5, 24, 32)
        head = sv.frames.head(5)
        assert head.shape == (5, 24, 32, 3) and len(list(head)) == 5
        assert (np.asarray(head) == rec.frames[:5]).all()
        with pytest.raises(IndexError):
            head[5]
        part = sv.frames.part(3, 19)  # a window of a long clip: indexed from its first frame
        assert part.shape == (16, 24, 32, 3) and (part[0] == rec.frames[3]).all()
        assert (part[np.array([15, 0])] == rec.frames[[18, 3]]).all() and (part[-1] == rec.frames[18]).all()
        assert (np.asarray(part.part(2, 5)) == rec.frames[5:8]).all() and (
            part.head(2)[:] == rec.frames[3:5]
        ).all()
        assert (np.concatenate([c for _, c in part.chunks(7)]) == rec.frames[3:19]).all()
        assert len(sv.frames.part(18, 40)) == 2 and len(sv.frames.part(25, 30)) == 0
        with pytest.raises(TypeError):
            sv.frames[::2]
        copy = pickle.loads(pickle.dumps(sv.flow_valid.head(3)))  # reopens the file
        assert (copy[:] == ~rec.occlusion_forward[:3]).all()


def test_every_read_is_held_to_the_array_limit_at_its_allocated_size(tmp_path, monkeypatch):
    vs, _ = _stored(tmp_path)
    sv = StoredVideo(vs.path("clip"))
    one = 24 * 32 * 2 * 4  # a flow frame once float32 (the file holds float16: half of it)
    monkeypatch.setenv("ZOOCTL_MAX_ARRAY_MB", str(3.5 * one / 2**20))
    assert sv.flow_forward[0:3].shape == (3, 24, 32, 2)
    with pytest.raises(StoreError, match="4 frames of flow/forward take"):
        sv.flow_forward[0:4]
    sv.close()


def test_a_damaged_video_file_is_one_clear_error(tmp_path):
    vs, _ = _stored(tmp_path)
    with h5py.File(vs.path("clip"), "a") as f:
        del f["masks"]
        f.create_dataset("masks", data=np.zeros((19, 24, 32), np.uint8))
    with pytest.raises(StoreError, match="is damaged: frames"):
        StoredVideo(vs.path("clip"))


def test_the_fit_of_a_stored_video_reads_frames_masks_and_flow_a_few_at_a_time(tmp_path):
    """Under an array read limit smaller than the video's frames, masks and flow, a whole fit with
    every output succeeds: nothing reads the frames, the masks or the flow whole."""
    from cli_helpers import zooctl
    from fit_helpers import tiny_overrides

    from zooctl.procedural import build_animal
    from zooctl.store.bank import Bank

    store = tmp_path / "store"
    vs, rec = _stored(tmp_path, t=140, h=96, w=128)
    Bank(store).add(build_animal("quadruped", name="quadruped"))
    frames_mb = rec.frames.nbytes / 2**20
    flow_mb = rec.flow_forward.nbytes / 2**20
    limit = 1.0
    assert frames_mb > limit and flow_mb > limit and rec.masks.nbytes / 2**20 > limit
    cfg = tmp_path / "tiny.json"
    cfg.write_text(json.dumps(tiny_overrides()))
    r = zooctl(
        "fit", "clip", "--template", "quadruped", "--config", str(cfg), "--name", "long",
        store=store, env={"ZOOCTL_MAX_ARRAY_MB": str(limit)}, timeout=600,
    )  # fmt: skip
    assert r.code == 0, r.err
    record = json.loads((store / "fits" / "long" / "record.json").read_text())
    assert record["status"] == "done" and record["frames"] == 140
    assert {"usd", "glb", "overlay"} <= set(record["outputs"])


def test_stages_get_iterations_in_proportion_to_a_long_clip():
    from fit_helpers import tiny_fit_config

    cfg = tiny_fit_config(iters=10)
    assert cfg.schedule_frames == 100
    assert cfg.stage(2, 60).iters == 10 and cfg.stage(2, 100).iters == 10
    assert cfg.stage(2, 250).iters == 25 and cfg.stage(1, 301).iters == 31
    cfg.schedule_frames = 0
    assert cfg.stage(2, 1000).iters == 10


def test_whole_sequence_terms_hold_each_frame_of_a_long_clip_as_firmly():
    """Smoothness, root smoothness and the rest-pose prior are means over all frames: past
    schedule_frames they are scaled by T / schedule_frames, so a frame's share stays that of a
    clip of schedule_frames frames (a 4x longer clip held its frames 4x more loosely before)."""
    import torch

    from zooctl.fit.config import preset
    from zooctl.fit.losses import MaskTargets
    from zooctl.fit.scene import FitScene
    from zooctl.fit.stages import StageRunner, Targets
    from zooctl.rig.synthetic import tube_asset

    asset = tube_asset(bones=3, rings_per_bone=2, segments=8, bone_length=0.3, radius=0.05)
    terms = {}
    for T in (50, 200):
        torch.manual_seed(0)
        scene = FitScene(asset, T, 16, 16, focal=20.0, hidden=8)
        with torch.no_grad():
            scene.root_translation[:, 2] = -2.0
            scene.rotations.copy_(scene.rotations + 0.1 * torch.randn_like(scene.rotations))
            scene.root_translation[:, 0] = torch.linspace(0, 1, T) ** 2
        targets = Targets(MaskTargets.build(np.ones((T, 16, 16), np.float32), seed=0))
        cfg = preset("fast")
        runner = StageRunner(scene, targets, cfg, 2)
        assert runner.sequence_scale == max(1.0, T / 100)
        terms[T] = runner.loss(torch.arange(4))[1]
        cfg.schedule_frames = 0
        terms[T, "off"] = StageRunner(scene, targets, cfg, 2).loss(torch.arange(4))[1]
    for k in ("smooth", "pose", "root_smooth"):
        assert terms[50][k] == pytest.approx(terms[50, "off"][k])
        assert terms[200][k] == pytest.approx(2.0 * terms[200, "off"][k], rel=1e-5)
