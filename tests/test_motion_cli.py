"""`zooctl motion ...`, `zooctl animate`, `zooctl bench motion`, the motion store and the plugin
(issue 8), end to end on a procedural animal with a tiny prior."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import run_inprocess

from zooctl.errors import AlreadyExistsError, NotFoundError, StoreError
from zooctl.motion.model import MotionConfig
from zooctl.motion.prior import PonymationPrior
from zooctl.store.motion_store import MotionStore

SCHEMA = Path(__file__).resolve().parents[1] / "schemas" / "motion_prior.schema.json"
TINY = [
    "--arch",
    "ponymation",
    "--width",
    "16",
    "--layers",
    "1",
    "--latent",
    "8",
    "--length",
    "8",
    "--epochs",
    "1",
    "--batch-size",
    "32",
]


pytestmark = pytest.mark.usefixtures("one_thread")  # see conftest


@pytest.fixture(scope="module")
def seeded_store(tmp_path_factory) -> Path:
    """A store whose bank holds a procedural quadruped and a fish (clips: walk, trot, idle / swim, idle)."""
    from zooctl.procedural import build_animal
    from zooctl.store.bank import Bank

    root = tmp_path_factory.mktemp("motion") / "store"
    bank = Bank(root)
    bank.add(build_animal("quadruped"))
    bank.add(build_animal("fish"))
    return root


def _validate(cfg: dict) -> None:
    import jsonschema

    jsonschema.validate(cfg, json.loads(SCHEMA.read_text()))


def test_train_list_show_animate_bench_rm(seeded_store, capsys, monkeypatch, tmp_path):
    monkeypatch.setenv("ZOOCTL_STORE", str(seeded_store))
    r = run_inprocess(capsys, "motion", "train", "--all", "--name", "tiny", "--holdout", "0.4", *TINY)
    assert r.code == 0, r.err
    assert "trained motion prior 'tiny'" in r.out
    cfg = json.loads((seeded_store / "motion" / "tiny" / "config.json").read_text())
    _validate(cfg)
    assert cfg["training"]["assets"] == ["fish", "quadruped"]
    held = cfg["training"]["holdout"]
    assert set(held) == {"fish", "quadruped"}
    trained = set(cfg["training"]["sequences"])
    assert not any(f"{a}/{c}" in trained for a, cs in held.items() for c in cs)
    assert (seeded_store / "motion" / "tiny" / "loss.png").read_bytes()[:4] == b"\x89PNG"

    r = run_inprocess(capsys, "motion", "list", "--json")
    assert r.code == 0 and [c["name"] for c in r.json()] == ["tiny"]
    r = run_inprocess(capsys, "motion", "show", "tiny")
    assert r.code == 0 and "held out: 2 clips of 2 assets" in r.out

    out = tmp_path / "anim"
    r = run_inprocess(
        capsys,
        "animate",
        "quadruped",
        "--sample",
        "2",
        "--frames",
        "12",
        "--seed",
        "3",
        "--out",
        str(out),
        "--size",
        "48",
        "--json",
    )
    assert r.code == 0, r.err
    manifest = r.json()
    assert manifest["prior"] == "tiny" and manifest["samples"] == 2
    assert [Path(p).name for p in manifest["files"]["usd"]] == [
        "quadruped_sample00.usd",
        "quadruped_sample01.usd",
    ]
    assert Path(manifest["files"]["preview"][0]).stat().st_size > 0
    assert Path(manifest["files"]["contact_sheet"][0]).stat().st_size > 0
    # The preview renders every sixth frame (5 of the clip's 30 per second) and plays them at
    # 5 fps: the 12 sampled frames last as long, from 2 renders.
    import imageio_ffmpeg

    n_frames, secs = imageio_ffmpeg.count_frames_and_secs(manifest["files"]["preview"][0])
    assert n_frames == 2 and abs(secs - 0.4) < 0.05

    # The exported motion is the sampled one: re-sample with the same seed and compare with the GLB.
    from zooctl.io.gltf_import import load_gltf
    from zooctl.store.bank import Bank

    quad = Bank(seeded_store).get("quadruped")
    rots = MotionStore(seeded_store).load("tiny").sample(quad, n=2, frames=12, seed=3)
    back = load_gltf(Path(manifest["files"]["glb"][1]), "back")
    (clip,) = back.clips.values()
    assert clip.num_frames == 12
    assert np.allclose(np.abs((clip.rotations * rots[1]).sum(-1)), 1.0, atol=1e-4)

    from pxr import Usd, UsdSkel

    stage = Usd.Stage.Open(manifest["files"]["usd"][0])
    anims = [p for p in stage.Traverse() if p.IsA(UsdSkel.Animation)]
    assert len(anims) == 1
    assert len(UsdSkel.Animation(anims[0]).GetRotationsAttr().GetTimeSamples()) == 12

    r = run_inprocess(
        capsys,
        "bench",
        "motion",
        "--prior",
        "tiny",
        "--samples",
        "4",
        "--repeats",
        "1",
        "--frames",
        "12",
        "--seeds",
        "2",
        "--json",
    )
    assert r.code == 0, r.err
    res = r.json()
    assert set(res["table"]) == {"ponymation", "pca", "retrieval", "real"}
    assert res["table"]["ponymation"]["recon_mpjpe"] is not None and res["table"]["pca"]["mcd"] is not None
    # Two sampling seeds: the table is their mean, with their spread beside it.
    assert res["seeds"] == [0, 1] and len(res["per_seed"]) == 2
    mcd = [t["pca"]["mcd"] for t in res["per_seed"]]
    assert res["table"]["pca"]["mcd"] == pytest.approx(np.mean(mcd))
    assert res["table_sd"]["pca"]["mcd"] == pytest.approx(np.std(mcd)) and np.std(mcd) > 0
    assert res["sampling"]["asset"] == "quadruped"

    r = run_inprocess(capsys, "motion", "rm", "tiny")
    assert r.code == 0
    assert not (seeded_store / "motion" / "tiny").exists()
    assert run_inprocess(capsys, "motion", "list", "--json").json() == []


def test_bad_requests_are_one_line_errors(seeded_store, capsys, monkeypatch, tmp_path):
    monkeypatch.setenv("ZOOCTL_STORE", str(seeded_store))
    r = run_inprocess(capsys, "motion", "train", *TINY)
    assert r.code == 2 and "--assets" in r.err and "Traceback" not in r.err
    r = run_inprocess(capsys, "motion", "train", "--assets", "unicorn", *TINY)
    assert r.code == 2 and "no asset named 'unicorn'" in r.err
    r = run_inprocess(capsys, "motion", "train", "--all", "--width", "30", "--layers", "1")
    assert r.code == 2 and "divisible" in r.err
    r = run_inprocess(capsys, "motion", "show", "nope")
    assert r.code == 2 and "no motion prior named 'nope'" in r.err
    r = run_inprocess(capsys, "motion", "rm", "nope")
    assert r.code == 2
    empty = tmp_path / "empty"
    monkeypatch.setenv("ZOOCTL_STORE", str(empty))
    from zooctl.procedural import build_animal
    from zooctl.store.bank import Bank

    Bank(empty).add(build_animal("snake"))
    r = run_inprocess(capsys, "animate", "snake", "--out", str(tmp_path / "x"))
    assert r.code == 2 and "no motion prior" in r.err and "zooctl motion train" in r.err
    r = run_inprocess(capsys, "animate", "dragon")
    assert r.code == 2 and "'dragon' is neither a bank asset nor a fit" in r.err
    r = run_inprocess(capsys, "animate")
    assert r.code == 2 and "either TARGET" in r.err and "Traceback" not in r.err
    r = run_inprocess(capsys, "animate", "snake", "--image", str(tmp_path / "a.png"))
    assert r.code == 2 and "either TARGET" in r.err
    r = run_inprocess(capsys, "animate", "snake", "--masks", "auto")
    assert r.code == 2 and "only apply with --image" in r.err
    r = run_inprocess(capsys, "animate", "--image", str(tmp_path / "missing.png"))
    assert r.code == 2 and "not an image file" in r.err


def test_animate_a_photo_then_its_fit(seeded_store, capsys, monkeypatch, tmp_path):
    """`animate --image`: a single-photo fit, then samples on the fitted character; the fit is then
    a TARGET by name (`fit:NAME`)."""
    from PIL import Image

    from zooctl.benchdata.make import make_video
    from zooctl.store.bank import Bank
    from zooctl.store.fits import FitStore

    monkeypatch.setenv("ZOOCTL_STORE", str(seeded_store))
    r = run_inprocess(capsys, "motion", "train", "--assets", "quadruped", "--name", "photo-prior", *TINY)
    assert r.code == 0, r.err
    quad = Bank(seeded_store).get("quadruped")
    with np.load(make_video(quad, tmp_path / "v", frames=1, size=64, seed=5) / "video.npz") as z:
        frame, mask = z["frames"][0], z["masks"][0]
    photo = tmp_path / "cat.png"
    Image.fromarray(frame).save(photo)
    (tmp_path / "cat_mask").mkdir()
    Image.fromarray(mask.astype(np.uint8) * 255).save(tmp_path / "cat_mask" / "cat.png")
    small = tmp_path / "small.json"
    small.write_text(json.dumps({"stage1": {"iters": 3, "batch": 1}, "stage2": {"iters": 3, "batch": 1}}))
    args = ["--sample", "2", "--frames", "12", "--prior", "photo-prior", "--no-preview", "--json"]
    r = run_inprocess(
        capsys,
        "animate",
        "--image",
        str(photo),
        "--masks",
        str(tmp_path / "cat_mask"),
        "--template",
        "quadruped",
        "--fit-config",
        str(small),
        "--out",
        str(tmp_path / "a1"),
        *args,
    )
    assert r.code == 0, r.err
    manifest = r.json()
    assert manifest["target"] == "cat" and len(manifest["files"]["usd"]) == 2
    fitted = FitStore(seeded_store).character("cat")
    assert fitted.num_joints == quad.num_joints
    assert all(Path(p).stat().st_size > 0 for p in manifest["files"]["glb"])
    r = run_inprocess(capsys, "animate", "fit:cat", "--out", str(tmp_path / "a2"), *args)
    assert r.code == 0, r.err
    assert Path(r.json()["files"]["usd"][1]).name == "cat_sample01.usd"
    assert run_inprocess(capsys, "motion", "rm", "photo-prior").code == 0


def test_bench_needs_held_out_clips(seeded_store, capsys, monkeypatch):
    root = seeded_store.parent / "noheld"
    monkeypatch.setenv("ZOOCTL_STORE", str(root))
    from zooctl.procedural import build_animal
    from zooctl.store.bank import Bank

    Bank(root).add(build_animal("fish"))
    assert run_inprocess(capsys, "motion", "train", "--assets", "fish", "--name", "all", *TINY).code == 0
    r = run_inprocess(capsys, "bench", "motion", "--prior", "all")
    assert r.code == 2 and "--holdout" in r.err


def _tiny_prior() -> PonymationPrior:
    return PonymationPrior(MotionConfig(width=16, layers=1, heads=4, latent=8, length=8))


def test_store_writes_are_atomic_and_replace_is_explicit(tmp_path):
    store = MotionStore(tmp_path)
    prior = _tiny_prior()

    def boom(tmp: Path) -> None:
        prior.save(tmp, "p")
        raise RuntimeError("killed mid-write")

    with pytest.raises(RuntimeError):
        store.add("p", boom)
    assert store.names() == [] and list((tmp_path / "motion").iterdir()) == []

    with pytest.raises(StoreError, match="without config.json"):
        store.add("p", lambda tmp: (tmp / "weights.pt").write_bytes(b"x"))
    store.add("p", lambda tmp: prior.save(tmp, "p"))
    _validate(store.config("p"))
    with pytest.raises(AlreadyExistsError):
        store.add("p", lambda tmp: prior.save(tmp, "p"))
    before = (tmp_path / "motion" / "p" / "weights.pt").stat().st_ino
    store.add("p", lambda tmp: prior.save(tmp, "p"), replace=True)
    assert (tmp_path / "motion" / "p" / "weights.pt").stat().st_ino != before
    assert [p.name for p in (tmp_path / "motion").iterdir()] == ["p"]  # no leftovers
    # A dead writer's temporary directory is invisible and cleaned up by the next write.
    dead = tmp_path / "motion" / ".q.999999999.abc.tmp"
    dead.mkdir()
    (dead / "config.json").write_text("{}")
    assert store.names() == ["p"]
    store.add("q", lambda tmp: prior.save(tmp, "q"))
    assert not dead.exists()
    store.remove("p")
    assert store.names() == ["q"]
    with pytest.raises(NotFoundError):
        store.remove("p")


def test_a_corrupt_prior_is_a_store_error(tmp_path):
    store = MotionStore(tmp_path)
    store.add("p", lambda tmp: _tiny_prior().save(tmp, "p"))
    (tmp_path / "motion" / "p" / "weights.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(StoreError, match="weights of motion prior .p. are unreadable"):
        store.load("p")


def test_the_prior_is_a_plugin_component(tmp_path):
    from zooctl.plugins import get_registry

    spec = get_registry().get("motion_prior", "ponymation")
    fresh = spec.create(width=16, layers=1, heads=4, latent=8)
    assert isinstance(fresh, PonymationPrior) and fresh.cfg.width == 16
    fresh.save(tmp_path / "p", "p")
    loaded = spec.create(path=tmp_path / "p")
    assert loaded.cfg == fresh.cfg
    assert os.path.isfile(tmp_path / "p" / "weights.pt")
