"""The BVH exporter: `bank export --format bvh` writes a file whose skeleton and motion, read back,
give the asset's own forward kinematics; assimp (when installed) imports it too."""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pytest
from cli_helpers import run_inprocess

from zooctl.io.bvh import read_bvh


def test_bank_export_bvh_round_trip(store, tmp_path, capsys):
    from zooctl.store.bank import Bank

    assert run_inprocess(capsys, "bank", "seed", "--plan", "quadruped", "--no-variants").code == 0
    asset = Bank.open(store).get("quadruped")
    r = run_inprocess(
        capsys, "bank", "export", "quadruped", "--format", "bvh", "--clip", "trot", "-o", str(tmp_path)
    )
    assert r.code == 0, r.err
    path = tmp_path / "quadruped.bvh"
    bvh = read_bvh(path)
    clip = asset.clips["trot"]
    assert sorted(bvh.names) == sorted(asset.joint_names)  # depth-first in the file
    order = [bvh.names.index(n) for n in asset.joint_names]
    parent_name = {n: (bvh.names[p] if p >= 0 else None) for n, p in zip(bvh.names, bvh.parents)}
    assert [parent_name[n] for n in asset.joint_names] == [
        asset.joint_names[p] if p >= 0 else None for p in asset.parents
    ]
    assert bvh.motion.shape[0] == clip.num_frames and bvh.frame_time == pytest.approx(1 / clip.fps)
    local = clip.local_matrices()
    local[..., :3, :3] /= np.linalg.norm(local[..., :3, :3], axis=-2, keepdims=True)  # BVH has no scale
    want = asset.joint_transforms(local)[..., :3, 3]
    got = bvh.global_matrices()[:, order][..., :3, 3]
    np.testing.assert_allclose(got, want, atol=1e-4 * asset.size())
    # the whole asset: every clip one after the other
    r = run_inprocess(capsys, "bank", "export", "quadruped", "-o", str(tmp_path / "all.bvh"))
    assert r.code == 0, r.err
    assert read_bvh(tmp_path / "all.bvh").motion.shape[0] == sum(c.num_frames for c in asset.clips.values())
    r = run_inprocess(capsys, "bank", "export", "quadruped", "--format", "bvh", "--clip", "fly")
    assert r.code == 2 and "no clip 'fly'" in r.err


def test_assimp_reads_our_bvh(tmp_path):
    exe = shutil.which("assimp")
    if exe is None:
        pytest.skip("the assimp command is not installed (apt install assimp-utils)")
    from zooctl.io.bvh import save_bvh
    from zooctl.procedural import build_animal

    asset = build_animal("quadruped", name="quadruped")
    save_bvh(asset, tmp_path / "q.bvh", ["walk"])
    out = subprocess.run([exe, "info", str(tmp_path / "q.bvh")], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "Animations" in out.stdout and "Nodes" in out.stdout
