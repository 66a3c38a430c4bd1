"""The `ray` executor (plugins/zooctl-ray) on a local Ray instance: fits and bank adds in Ray
workers, stored once each by the driver; an interrupted batch resumed; the CLI joining Ray."""

from __future__ import annotations

import json

import pytest

ray = pytest.importorskip(
    "ray", reason="ray is not installed (pip install plugins/zooctl-ray; make test does)"
)
pytest.importorskip(
    "zooctl_ray", reason="the zooctl-ray plugin is not installed (pip install plugins/zooctl-ray)"
)

from batch_helpers import fit_inputs, fit_records, glb_files, temporaries, tiny_config  # noqa: E402
from cli_helpers import zooctl  # noqa: E402

from zooctl.executors import get_executor  # noqa: E402
from zooctl.pipelines.batch import BatchInterrupted, Progress, run_batch  # noqa: E402
from zooctl.pipelines.batch_bank import bank_task, commit_bank, plan_add  # noqa: E402
from zooctl.pipelines.batch_fit import commit_fit, fit_task, plan_fits, skip_finished  # noqa: E402
from zooctl.store.bank import Bank  # noqa: E402


@pytest.fixture(scope="module", autouse=True)
def local_ray():
    """One small Ray for the module (its start-up costs seconds): 2 CPUs, no dashboard."""
    ray.init(
        address="local",
        num_cpus=2,
        include_dashboard=False,
        object_store_memory=200 * 1024 * 1024,
        log_to_driver=False,
    )
    yield
    ray.shutdown()


def test_ray_runs_fits_and_bank_adds_and_the_driver_stores_them(tmp_path, store, monkeypatch):
    videos = fit_inputs(tmp_path, store, 3)
    items = plan_fits(videos, store, tiny_config(), template="a0", out_root=tmp_path / "out")
    ex = get_executor("ray", jobs=2)
    assert ex.name == "ray" and ex.slots == 2 and not ex.owned  # joined the running Ray
    report = run_batch(ex, fit_task, items, commit_fit)
    assert report.count("done") == 3, report.to_json()
    assert all(r.where and r.attempts == 1 for r in report.results)
    recs = fit_records(store)
    assert sorted(recs) == ["a0", "a1", "a2"] and {r["status"] for r in recs.values()} == {"done"}
    assert (tmp_path / "out" / "a2" / "a2.usd").is_file()

    monkeypatch.setenv("ZOOCTL_EMBEDDERS", "silhouette")  # travels to the workers with each task
    bank = Bank.open(store)
    add = plan_add(bank, glb_files(tmp_path, 2), views=True)
    report = run_batch(ex, bank_task, add, commit_bank)
    assert report.count("done") == 2, report.to_json()
    for name in ("m0", "m1"):
        views = bank.summary(name)["views"]
        assert views["count"] == 24 and set(views["embedders"]) == {"silhouette"}
    assert not temporaries(store)
    ex.close()
    assert ray.is_initialized()  # a Ray it did not start stays up


def test_ray_batch_interrupted_then_resumed_stores_each_fit_once(tmp_path, store):
    videos = fit_inputs(tmp_path, store, 4)
    items = plan_fits(videos, store, tiny_config(), template="a0", out_root=tmp_path / "out")
    commits: list[str] = []

    def commit(item, value):
        commits.append(item.key)
        return commit_fit(item, value)

    class CtrlC(Progress):
        def finished(self, result):
            raise KeyboardInterrupt

    with pytest.raises(BatchInterrupted) as exc:
        run_batch(get_executor("ray", jobs=2), fit_task, items, commit, progress=CtrlC())
    first = [r.key for r in exc.value.report.results]
    assert len(first) == 1 and commits == first
    report = run_batch(get_executor("ray", jobs=2), fit_task, items, commit, skip=skip_finished)
    assert report.count("skipped") == 1 and report.count("done") == 3
    assert sorted(commits) == ["a0", "a1", "a2", "a3"]  # each fit committed exactly once
    assert sorted(fit_records(store)) == ["a0", "a1", "a2", "a3"]


def test_cli_fit_joins_a_ray_cluster_by_address(tmp_path, store):
    videos = fit_inputs(tmp_path, store, 2)
    cfg = tmp_path / "tiny.json"
    cfg.write_text(json.dumps(tiny_config()))
    address = ray.get_runtime_context().gcs_address
    args = ["fit", *videos, "--template", "a0", "--config", str(cfg), "--out", str(tmp_path / "out")]
    r = zooctl(*args, "--executor", "ray", "--address", address, "--json", store=store)
    assert r.code == 0, r.err
    rep = r.json()
    assert rep["executor"] == "ray" and rep["done"] == 2
    r = zooctl(*args, "--executor", "ray", "--address", address, "--resume", "--json", store=store)
    assert r.code == 0 and r.json()["skipped"] == 2
    r = zooctl(*args, "--executor", "ray", "--address", address, store=store)  # the names are taken
    assert r.code == 2 and "exists already" in r.err and "done already" not in r.err, r.err
    r = zooctl(
        *args, "--executor", "ray", "--gpus-per-task", "1", "--address", address, "--replace", store=store
    )
    assert r.code == 2 and "has 0 GPUs" in r.err
