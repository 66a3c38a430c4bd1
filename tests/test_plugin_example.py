"""The example plugin package's renderer, articulation model, exporter, segmenter and flow estimator
are used by the commands that should use them: `zooctl fit --renderer pointsplat --articulation
rigid` (a tiny fit), `bank export --format ply`, `video add --segmenter backdrop --flow farneback`
and `motion train --kind example-loop` then `animate`.

The package is pip-installed into a private folder put on PYTHONPATH (not into the venv), so
tests running at the same time never see it; `tests/test_plugins.py` covers the venv install."""

from __future__ import annotations

import json
import math

import pytest
from cli_helpers import REPO, pip, zooctl

EXAMPLE = REPO / "plugins" / "zooctl-example"
TINY = {
    "fit_size": 48,
    "stage1": {"iters": 8, "batch": 6},
    "stage2": {"iters": 10, "batch": 3},
    "camera": {"azimuths": 4, "elevations": [0.0], "fov_candidates": [45.0]},
    "trials": {"candidates": 1},
}


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    """(env with the plugin on PYTHONPATH, store with the `worm` asset, a bench video of it)."""
    root = tmp_path_factory.mktemp("example")
    site = root / "site"
    pip("install", "--no-deps", "--no-build-isolation", "--target", str(site), str(EXAMPLE))
    env = {"PYTHONPATH": str(site), "ZOOCTL_VIEWS": "0", "OMP_NUM_THREADS": "1"}
    store = root / "store"
    toy = root / "worm.toyrig"
    assert zooctl("toyrig", "worm", "-o", str(toy), "--bones", "3", env=env).code == 0
    r = zooctl("bank", "add", str(toy), store=store, env=env)
    assert r.code == 0, r.err
    make = f"bench make --asset worm --out {root / 'videos'} --frames 6 --size 48"
    r = zooctl(*make.split(), store=store, env=env)
    assert r.code == 0, r.err
    return env, store, root


def test_plugin_components_are_listed(example):
    env, store, _ = example
    r = zooctl("plugins", "--json", env=env)
    regs = {p["name"]: p for p in r.json()["plugins"]}["toyrig"]["registers"]
    assert regs["renderer"] == ["pointsplat"] and regs["articulation_model"] == ["rigid"]
    assert regs["exporter"] == ["ply"]


def test_fit_uses_the_plugin_renderer_and_articulation_model(example):
    env, store, root = example
    cfg = root / "tiny.json"
    cfg.write_text(json.dumps(TINY))
    out = root / "fit"
    args = [
        "fit",
        str(root / "videos" / "worm"),
        "--template",
        "worm",
        "--config",
        str(cfg),
        "--out",
        str(out),
    ]
    r = zooctl(*args, "--renderer", "pointsplat", "--articulation", "rigid", "--json", store=store, env=env)
    assert r.code == 0, r.err
    rec = r.json()
    saved = (
        json.loads((out / "config.json").read_text()) if (out / "config.json").is_file() else rec["config"]
    )
    assert saved["articulation"] == "rigid"
    assert saved["stage1"]["renderer"] == saved["stage2"]["renderer"] == "pointsplat"
    assert rec["metrics"]["mask_iou"] > 0.3  # the splat silhouettes did pull the worm onto its masks
    # without the plugin the same names are one clear error
    r = zooctl(
        *args,
        "--renderer",
        "pointsplat",
        store=store,
        env={**env, "ZOOCTL_LOAD_PLUGINS": ""},
    )
    assert r.code == 2 and "no renderer named 'pointsplat'" in r.err and "Traceback" not in r.err


def test_bank_export_through_the_plugin_exporter(example):
    env, store, root = example
    r = zooctl("bank", "export", "worm", "--format", "ply", "-o", str(root), "--json", store=store, env=env)
    assert r.code == 0, r.err
    path = root / "worm.ply"
    assert r.json()["path"] == str(path)
    lines = path.read_text().splitlines()
    assert lines[0] == "ply" and lines[2] == "element vertex 156"  # (4 * 3 + 1) rings of 12
    r = zooctl("bank", "export", "worm", "-o", str(root / "w.ply"), store=store, env=env)  # suffix -> format
    assert r.code == 0 and (root / "w.ply").is_file(), r.err


def test_video_add_through_the_plugin_segmenter_and_flow_estimator(example, tmp_path):
    """`video add --segmenter backdrop --flow farneback`: a bright disc moving right over a plain
    backdrop is masked where it is, and its stored flow points right."""
    import cv2
    import numpy as np

    env, store, _ = example
    path = tmp_path / "disc.mp4"
    w, h, n = 96, 64, 8
    out = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 10, (w, h))
    for t in range(n):
        img = np.full((h, w, 3), (40, 90, 30), np.uint8)
        cv2.circle(img, (24 + 4 * t, 32), 12, (220, 200, 180), -1)
        out.write(img)
    out.release()
    r = zooctl(
        *f"video add {path} --name disc --segmenter backdrop --flow farneback --json".split(),
        store=store,
        env=env,
    )
    assert r.code == 0, r.err
    from zooctl.store.videos import VideoStore

    v = VideoStore.open(store).get("disc")
    got = {
        "seg": v.segmenter,
        "flow": v.flow_estimator,
        "cov": float(v.masks.mean()),
        "u": float(v.flow_forward[..., 0][v.masks[:-1]].mean()),
    }
    assert got["seg"]["name"] == "backdrop" and got["flow"]["name"] == "farneback"
    disc = math.pi * 12**2 / (w * h)
    assert 0.7 * disc < got["cov"] < 1.3 * disc
    assert got["u"] > 1.5  # about 4 px a frame to the right


def test_motion_train_and_animate_through_the_plugin_motion_prior(example, tmp_path):
    """`motion train --kind example-loop` trains the installed package's prior; `animate` samples it."""
    env, store, _ = example
    r = zooctl(*"motion train --assets worm --kind example-loop --name loop".split(), store=store, env=env)
    assert r.code == 0, r.err
    cfg = json.loads((store / "motion" / "loop" / "config.json").read_text())
    assert cfg["plugin"] == "example-loop"
    args = f"animate worm --prior loop --sample 2 --frames 30 --no-preview --json --out {tmp_path / 'a'}"
    r = zooctl(*args.split(), store=store, env=env)
    assert r.code == 0, r.err
    assert all(a > 1.0 for a in r.json()["amplitude_deg"])
