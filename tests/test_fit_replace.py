"""A finished fit is never clobbered: a name in use is refused up front, and `--replace` keeps the
old fit whole until the new one has finished (a failing or interrupted run leaves it as it was)."""

from __future__ import annotations

import json

import pytest
from cli_helpers import run_inprocess
from fit_helpers import tiny_fit_config

from zooctl.errors import AlreadyExistsError


@pytest.fixture(scope="module")
def tube(tmp_path_factory):
    from zooctl.benchdata.make import make_video
    from zooctl.rig.synthetic import tube_asset

    asset = tube_asset(bones=3, name="tube")
    return asset, make_video(asset, tmp_path_factory.mktemp("tube"), frames=4, size=40, seed=2)


@pytest.fixture
def fitted(tube, store):
    """A finished fit ``t`` (outputs in the store's fit folder) and a snapshot of its files."""
    from zooctl.fit.job import fit_job
    from zooctl.store.bank import Bank
    from zooctl.store.fits import FitStore

    asset, folder = tube
    Bank(store).add(asset)
    rec = fit_job(str(folder), store, tiny_fit_config(iters=2), name="t", template="tube", outputs=("loss",))
    fits = FitStore(store)
    return folder, fits, rec, _snapshot(fits.path("t"))


def _snapshot(folder):
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_a_name_in_use_is_refused_up_front(fitted, store, capsys):
    from zooctl.fit.job import fit_job

    folder, fits, _, before = fitted
    with pytest.raises(AlreadyExistsError, match="exists already"):
        fit_job(str(folder), store, tiny_fit_config(iters=2), name="t", template="tube")
    assert _snapshot(fits.path("t")) == before
    r = run_inprocess(capsys, "fit", str(folder), "--name", "t", "--template", "tube", "--iters", "1")
    assert r.code == 2 and "--replace" in r.err and "Traceback" not in r.err
    assert _snapshot(fits.path("t")) == before


@pytest.mark.parametrize("failure", [RuntimeError("boom"), KeyboardInterrupt()])
def test_a_failed_replacement_leaves_the_old_fit_whole(fitted, store, monkeypatch, failure):
    import zooctl.fit.job as job

    folder, fits, _, before = fitted

    def fail(*a, **k):
        raise failure

    monkeypatch.setattr(job, "fit_video", fail)
    with pytest.raises(type(failure)):
        job.fit_job(str(folder), store, tiny_fit_config(iters=2), name="t", template="tube", replace=True)
    assert fits.get("t")["status"] == "done"
    assert _snapshot(fits.path("t")) == before
    assert [p.name for p in fits.dir.iterdir()] == ["t"]  # no staging folder left behind


def test_replace_swaps_in_the_new_fit_with_its_paths(fitted, store):
    from zooctl.fit.job import fit_job

    folder, fits, old, _ = fitted
    rec = fit_job(
        str(folder),
        store,
        tiny_fit_config(iters=3),
        name="t",
        template="tube",
        outputs=("loss",),
        replace=True,
    )
    stored = fits.get("t")
    assert stored["status"] == "done" and stored["config"]["stage2"]["iters"] == 3
    assert rec["out"] == old["out"] == str(fits.path("t").resolve())
    for p in stored["outputs"].values():  # the record names files that exist where it says
        assert p.startswith(str(fits.path("t").resolve())) and (fits.path("t") / p.split("/")[-1]).is_file()
    fit_json = json.loads((fits.path("t") / "fit.json").read_text())
    assert fit_json["out"] == stored["out"] and ".replacing" not in json.dumps(fit_json)
    assert [p.name for p in fits.dir.iterdir()] == ["t"]


def test_replace_with_outputs_outside_the_store(tube, store, tmp_path):
    from zooctl.fit.job import fit_job
    from zooctl.store.bank import Bank
    from zooctl.store.fits import FitStore

    asset, folder = tube
    Bank(store).add(asset)
    out = tmp_path / "outs"
    cfg = tiny_fit_config(iters=2)
    fit_job(str(folder), store, cfg, name="t", template="tube", outputs=("loss",), out=out)
    first = (out / "fit.json").read_bytes()
    rec = fit_job(
        str(folder), store, cfg, name="t", template="tube", outputs=("loss",), out=out, replace=True
    )
    assert (out / "fit.json").read_bytes() != first
    assert rec["outputs"]["loss_png"] == str((out / "loss.png").resolve())
    assert json.loads((out / "fit.json").read_text())["out"] == str(out.resolve())
    assert FitStore(store).get("t")["out"] == str(out.resolve())
    assert not list(out.glob(".*.tmp"))


def test_a_new_fit_that_fails_is_listed_as_failed(tube, store, monkeypatch):
    import zooctl.fit.job as job
    from zooctl.store.bank import Bank
    from zooctl.store.fits import FitStore

    asset, folder = tube
    Bank(store).add(asset)

    def fail(*a, **k):
        raise RuntimeError("out of memory")

    monkeypatch.setattr(job, "fit_video", fail)
    with pytest.raises(RuntimeError):
        job.fit_job(str(folder), store, tiny_fit_config(iters=2), name="n", template="tube")
    rec = FitStore(store).get("n")
    assert rec["status"] == "failed" and "out of memory" in rec["error"]
