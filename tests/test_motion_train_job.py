"""`zooctl motion train` as a library job (issue 22/24): device-dependent defaults said in the
output, `--kind` trains any registered prior (the PCA baseline here), `--fits` trains on fitted
videos; and the preview's amplitude labels."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import run_inprocess

from zooctl.pipelines.motion_train import MotionTrainOptions

pytestmark = pytest.mark.usefixtures("one_thread")  # see conftest
SCHEMA = Path(__file__).resolve().parents[1] / "schemas" / "motion_prior.schema.json"


@pytest.fixture(scope="module")
def store_root(tmp_path_factory) -> Path:
    """A bank with a procedural quadruped and fish, and two finished "fits" of the quadruped (its
    walk and trot as the fitted motion of a character with the quadruped's skeleton)."""
    from zooctl.procedural import build_animal
    from zooctl.store.bank import Bank
    from zooctl.store.fits import FitStore

    root = tmp_path_factory.mktemp("job") / "store"
    bank = Bank(root)
    quad = build_animal("quadruped")
    bank.add(quad)
    bank.add(build_animal("fish"))
    fits = FitStore(root)
    for name, clip in (("walkvid", "walk"), ("trotvid", "trot")):
        fits.save_record(name, {"template": "quadruped", "status": "done"})
        c = quad.clips[clip]
        fits.save_character(
            name, dataclasses.replace(quad, name=name, clips={"fit": dataclasses.replace(c, name="fit")})
        )
    fits.save_record("unfinished", {"template": "quadruped", "status": "interrupted"})
    return root


def test_defaults_follow_the_device():
    cpu, note = MotionTrainOptions().resolve()
    assert (cpu.arch, cpu.width, cpu.layers, cpu.latent) == ("trajectory", 64, 2, 64)
    assert "CPU" in note and "trajectory 64 x 2" in note
    cuda, note = MotionTrainOptions(device="cuda").resolve()
    assert (cuda.arch, cuda.width, cuda.layers) == ("ponymation", 256, 4) and "Ponymation" in note
    mine, note = MotionTrainOptions(width=32, batch_size=8).resolve()
    assert (mine.width, mine.layers, mine.batch_size, mine.latent) == (32, 2, 8, 32)


def test_kind_pca_trains_stores_and_animates(store_root, capsys, monkeypatch, tmp_path):
    import jsonschema

    monkeypatch.setenv("ZOOCTL_STORE", str(store_root))
    r = run_inprocess(
        capsys, "motion", "train", "--all", "--kind", "pca", "--name", "pca", "--holdout", "0.3"
    )
    assert r.code == 0, r.err
    cfg = json.loads((store_root / "motion" / "pca" / "config.json").read_text())
    jsonschema.validate(cfg, json.loads(SCHEMA.read_text()))
    assert cfg["plugin"] == "pca" and set(cfg["training"]["skeletons"]) == {"quadruped", "fish"}
    args = ["--sample", "2", "--frames", "40", "--prior", "pca", "--no-preview", "--json"]
    r = run_inprocess(capsys, "animate", "quadruped", "--out", str(tmp_path / "a"), *args)
    assert r.code == 0, r.err
    m = r.json()
    assert len(m["files"]["glb"]) == 2 and all(a > 1.0 for a in m["amplitude_deg"])  # it moves
    r = run_inprocess(capsys, "motion", "train", "--all", "--kind", "nope", "--name", "x")
    assert r.code == 2 and "nope" in r.err and "Traceback" not in r.err


def test_training_on_fits(store_root, capsys, monkeypatch):
    monkeypatch.setenv("ZOOCTL_STORE", str(store_root))
    tiny = ["--width", "16", "--layers", "1", "--latent", "8", "--length", "8", "--epochs", "1"]
    r = run_inprocess(capsys, "motion", "train", "--fits", "walkvid,trotvid", "--name", "fromfits", *tiny)
    assert r.code == 0, r.err
    assert "trajectory 16 x 1" in r.out and "2 fits" in r.err
    cfg = json.loads((store_root / "motion" / "fromfits" / "config.json").read_text())
    assert sorted(cfg["training"]["sequences"]) == ["fit:trotvid", "fit:walkvid"]
    assert len(cfg["training"]["skeletons"]) == 1  # fits of one template pool
    # --all-fits skips the unfinished fit; with bank clips too
    r = run_inprocess(capsys, "motion", "train", "--all-fits", "--assets", "fish", "--name", "both", *tiny)
    assert r.code == 0, r.err
    cfg = json.loads((store_root / "motion" / "both" / "config.json").read_text())
    assert {s.split("/")[0] for s in cfg["training"]["sequences"]} == {"fish", "fit:trotvid", "fit:walkvid"}
    r = run_inprocess(capsys, "motion", "train", "--fits", "unfinished", "--name", "x", *tiny)
    assert r.code == 2 and "no fitted character" in r.err
    r = run_inprocess(capsys, "motion", "train", "--fits", "ghost", "--name", "x", *tiny)
    assert r.code == 2 and "no fit named 'ghost'" in r.err


def test_a_step_budget_stops_training_and_is_recorded(store_root, capsys, monkeypatch):
    import jsonschema

    monkeypatch.setenv("ZOOCTL_STORE", str(store_root))
    tiny = ["--width", "16", "--layers", "1", "--latent", "8", "--length", "8", "--epochs", "50"]
    r = run_inprocess(capsys, "motion", "train", "--all", "--name", "steps", "--max-steps", "7", *tiny)
    assert r.code == 0, r.err
    assert "7 steps or 20 min budget" in r.err and "(stopped at --max-steps)" in r.out
    cfg = json.loads((store_root / "motion" / "steps" / "config.json").read_text())
    jsonschema.validate(cfg, json.loads(SCHEMA.read_text()))
    assert cfg["training"]["steps"] == 7 and cfg["training"]["max_steps"] == 7
    r = run_inprocess(capsys, "motion", "train", "--all", "--name", "x", "--max-steps", "0", *tiny)
    assert r.code == 2 and "Traceback" not in r.err


def test_amplitude_of_a_statue_is_zero(store_root):
    from zooctl.pipelines.animate import motion_amplitude, reference_clip
    from zooctl.store.bank import Bank

    quad = Bank(store_root).get("quadruped")
    still = np.repeat(quad.clips["walk"].rotations[:1], 30, 0)
    assert motion_amplitude(quad, still) < 0.01  # float32 rounding
    assert motion_amplitude(quad, quad.clips["trot"].rotations) > 5.0
    assert reference_clip(quad) in ("walk", "trot")


def test_a_third_party_prior_trains_and_animates(store_root, capsys, monkeypatch, tmp_path):
    """The example plugin's prior (registered in-process here; installed, its entry point does it)
    goes through `motion train --kind` and `animate` like a built-in one."""
    import importlib.util
    import sys

    from zooctl import plugins

    path = (
        Path(__file__).resolve().parents[1]
        / "plugins"
        / "zooctl-example"
        / "zooctl_example"
        / "motion_prior.py"
    )
    spec = importlib.util.spec_from_file_location("example_motion_prior", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    monkeypatch.setenv("ZOOCTL_STORE", str(store_root))
    plugins.get_plugin_manager().register(module, "example-motion-test")
    try:
        r = run_inprocess(
            capsys, "motion", "train", "--assets", "quadruped", "--kind", "example-loop", "--name", "loop"
        )
        assert r.code == 0, r.err
        cfg = json.loads((store_root / "motion" / "loop" / "config.json").read_text())
        assert cfg["plugin"] == "example-loop" and cfg["name"] == "loop"
        import jsonschema

        jsonschema.validate(cfg, json.loads(SCHEMA.read_text()))
        args = ["--sample", "2", "--frames", "30", "--prior", "loop", "--no-preview", "--json"]
        r = run_inprocess(capsys, "animate", "quadruped", "--out", str(tmp_path / "l"), *args)
        assert r.code == 0, r.err
        assert all(a > 1.0 for a in r.json()["amplitude_deg"])
    finally:
        plugins.reset()
        sys.modules.pop(spec.name, None)
