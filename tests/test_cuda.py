"""The CUDA path end to end: the same CLI commands as on the CPU with ``--device cuda``.

Skipped where PyTorch sees no CUDA device (CI); run on a GPU machine with
``pytest tests/test_cuda.py``. Small on purpose, like test_fit_e2e.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from cli_helpers import run_inprocess
from fit_helpers import small_quadruped_video

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="PyTorch sees no CUDA device")

TINY_PRIOR = ["--arch", "ponymation", "--width", "16", "--layers", "1", "--epochs", "2", "--batch-size", "8"]


@pytest.fixture(scope="module")
def store_and_video(tmp_path_factory):
    return small_quadruped_video(tmp_path_factory.mktemp("cuda"))


def _fit(capsys, monkeypatch, store: Path, folder: Path, cfg: Path, device: str) -> dict:
    monkeypatch.setenv("ZOOCTL_STORE", str(store))
    monkeypatch.chdir(store.parent)
    name = f"quad_{device}"
    r = run_inprocess(
        capsys, "fit", str(folder), "--template", "quadruped", "--config", str(cfg), "--name", name,
        "--device", device, "--seed", "0", "--json",
    )  # fmt: skip
    assert r.code == 0, r.err
    return json.loads((store / "fits" / name / "record.json").read_text())


def test_fit_on_cuda_writes_every_output_and_matches_the_cpu_fit(store_and_video, capsys, monkeypatch):
    store, folder, cfg = store_and_video
    gpu = _fit(capsys, monkeypatch, store, folder, cfg, "cuda")
    cpu = _fit(capsys, monkeypatch, store, folder, cfg, "cpu")
    assert gpu["config"]["device"] == "cuda"
    for key in ("usd", "glb", "overlay", "loss_png", "fit_json"):
        assert Path(gpu["outputs"][key]).stat().st_size > 0, key
    m, c = gpu["metrics"], cpu["metrics"]
    for k in ("mask_iou", "novel_view_iou", "miou", "joint"):
        assert m[k] is not None and np.isfinite(m[k]), k
    # Same seed, same steps: the devices' float arithmetic differs, the fit does not.
    assert abs(m["mask_iou"] - c["mask_iou"]) < 0.05, (m["mask_iou"], c["mask_iou"])


def test_motion_train_and_animate_on_cuda(store_and_video, capsys, monkeypatch, tmp_path):
    store, _, _ = store_and_video
    monkeypatch.setenv("ZOOCTL_STORE", str(store))
    r = run_inprocess(capsys, "motion", "train", "--all", "--name", "gpu", "--device", "cuda", *TINY_PRIOR)
    assert r.code == 0, r.err
    out = tmp_path / "anim"
    r = run_inprocess(
        capsys, "animate", "quadruped", "--prior", "gpu", "--sample", "2", "--frames", "40",
        "--device", "cuda", "--out", str(out), "--size", "48", "--json",
    )  # fmt: skip
    assert r.code == 0, r.err
    files = r.json()["files"]
    assert len(files["usd"]) == 2 and all(Path(p).stat().st_size > 0 for p in files["glb"])


def test_the_two_starts_side_by_side_on_cuda_are_the_two_one_after_another(tmp_path):
    """``trials.workers`` 2 on CUDA: the two starts run in two processes on the one GPU and agree
    with the two one after another in this process (the default on CUDA) within float order."""
    from test_fit_start_trial import TINY

    from zooctl.benchdata.make import make_video
    from zooctl.fit.config import FitConfig
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.named_start import start_trial
    from zooctl.fit.trial_pool import trial_threads
    from zooctl.rig.synthetic import tube_asset

    thin = tube_asset(bones=3, name="thin")
    video = load_fit_video(make_video(thin, tmp_path / "v", frames=6, size=32, seed=0))
    runs = []
    for workers in (0, 2):
        cfg = FitConfig.from_dict(
            {**TINY, "device": "cuda", "trials": {**TINY["trials"], "workers": workers}}
        )
        assert bool(trial_threads(cfg, 2)) == (workers == 2)
        runs.append(start_trial(video, thin, cfg, None))
    one, two = runs
    a, b = one.view["start_trial"], two.view["start_trial"]
    assert a["kept"] == b["kept"]
    for k in ("greedy", "steady"):
        assert a["loss"][k] == pytest.approx(b["loss"][k], abs=1e-4)
    for k, v in one.state["scene"].items():
        assert torch.allclose(v.cpu(), two.state["scene"][k].cpu(), atol=1e-4), k
