"""`zooctl.io.export_worker`: exports written by a second process are the files the command's own
process writes, its errors come back whole, and what cannot go to the worker (or a worker that is
gone) is written here instead."""

from __future__ import annotations

import os
import pickle
import sys
import textwrap

import pytest

from zooctl.errors import UsageError
from zooctl.io.asset_export import export_asset, resolve_export
from zooctl.io.export_worker import ExportWorker
from zooctl.procedural import build_animal


@pytest.fixture(scope="module")
def asset():
    return build_animal("quadruped")


def pid_exporter(tmp_path, name: str):
    """An exporter whose files hold the id of the process that wrote them, from a module written
    to ``tmp_path / name``."""
    folder = tmp_path / name
    folder.mkdir()
    (folder / f"{name}.py").write_text(
        textwrap.dedent(
            """
            import os
            from zooctl.components import ExporterSpec

            def save(asset, path, clips=None, **options):
                path.write_text(f"{os.getpid()} {asset.name} {clips}")

            SPEC = ExporterSpec("pid", ("pid",), save)
            """
        )
    )
    sys.path.insert(0, str(folder))
    try:
        return __import__(name).SPEC, folder
    finally:
        sys.path.remove(str(folder))


def test_worker_writes_the_same_files(asset, tmp_path):
    clip = next(iter(asset.clips))
    jobs, expected = [], []
    (tmp_path / "worker").mkdir()
    for fmt in ("usd", "usda", "glb"):
        spec = resolve_export(None, fmt, asset.name)[0]
        jobs.append((spec, tmp_path / "worker" / f"{asset.name}.{fmt}", [clip]))
        expected.append(export_asset(asset, tmp_path / f"{asset.name}.{fmt}", fmt, clips=[clip]))
    with ExportWorker([spec for spec, _, _ in jobs]) as worker:
        seconds = worker.submit(asset, jobs).result(timeout=120)
    assert seconds > 0
    for (_, path, _), ref in zip(jobs, expected, strict=True):
        assert path.read_bytes() == ref.read_bytes(), path.name


def test_the_exporter_runs_in_the_worker(asset, tmp_path, monkeypatch):
    spec, folder = pid_exporter(tmp_path, "pid_exporter_shared")
    monkeypatch.setenv("PYTHONPATH", str(folder))  # the worker can import the exporter's module
    with ExportWorker([spec]) as worker:
        worker.submit(asset, [(spec, tmp_path / "a.pid", ["walk"])]).result(timeout=120)
    pid, name, clips = (tmp_path / "a.pid").read_text().split(" ", 2)
    assert int(pid) != os.getpid()
    assert (name, clips) == (asset.name, "['walk']")


def test_what_the_worker_cannot_import_is_written_here(asset, tmp_path):
    spec, _ = pid_exporter(tmp_path, "pid_exporter_local")  # on no path the worker has
    with ExportWorker([spec]) as worker:
        worker.submit(asset, [(spec, tmp_path / "b.pid", None)]).result(timeout=120)
        # the stream stays readable after a request the worker could not load
        worker.submit(asset, [(spec, tmp_path / "c.pid", None)]).result(timeout=120)
    for f in ("b.pid", "c.pid"):
        assert int((tmp_path / f).read_text().split()[0]) == os.getpid()


def test_a_save_that_does_not_pickle_is_written_here(asset, tmp_path):
    from zooctl.components import ExporterSpec

    spec = ExporterSpec("lam", ("lam",), lambda a, path, clips=None: path.write_text(str(os.getpid())))
    with pytest.raises((pickle.PicklingError, AttributeError, TypeError)):
        pickle.dumps(spec)
    with ExportWorker([spec]) as worker:
        worker.submit(asset, [(spec, tmp_path / "x.lam", None)]).result(timeout=120)
    assert int((tmp_path / "x.lam").read_text()) == os.getpid()


def test_a_worker_that_is_gone_leaves_the_writing_here(asset, tmp_path, monkeypatch):
    spec, folder = pid_exporter(tmp_path, "pid_exporter_gone")
    monkeypatch.setenv("PYTHONPATH", str(folder))  # it could have written this one
    with ExportWorker([spec]) as worker:
        worker._proc.kill()
        worker._proc.wait()
        worker.submit(asset, [(spec, tmp_path / "d.pid", None)]).result(timeout=120)
    assert int((tmp_path / "d.pid").read_text().split()[0]) == os.getpid()


def test_errors_come_back_whole(asset, tmp_path):
    spec, _, _ = resolve_export(None, "glb", asset.name)
    missing = tmp_path / "no" / "such" / "x.glb"
    with pytest.raises(UsageError) as here:
        export_asset(asset, missing, "glb")
    with ExportWorker([spec]) as worker:
        with pytest.raises(UsageError) as there:
            worker.submit(asset, [(spec, missing, None)]).result(timeout=120)
    assert (there.value.message, there.value.hint) == (here.value.message, here.value.hint)
    assert there.value.hint


def test_zooctl_errors_pickle_with_their_hint():
    err = pickle.loads(pickle.dumps(UsageError("bad", hint="do this")))
    assert type(err) is UsageError and (err.message, err.hint, str(err)) == ("bad", "do this", "bad")


def test_without_an_interpreter_to_start_it_writes_here(asset, tmp_path, monkeypatch):
    spec, _ = pid_exporter(tmp_path, "pid_exporter_noexe")
    monkeypatch.setattr(sys, "executable", "")  # an embedded Python has none
    with ExportWorker([spec]) as worker:
        worker.submit(asset, [(spec, tmp_path / "e.pid", None)]).result(timeout=120)
    assert int((tmp_path / "e.pid").read_text().split()[0]) == os.getpid()
