"""Batches on the built-in `local` executor: every result stored once, failures per item,
crashed workers retried, an interrupted batch resumed (issue 23)."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from batch_helpers import fit_inputs, fit_records, glb_files, temporaries, tiny_config
from cli_helpers import zooctl

from zooctl.cli.batch_opts import stop_code
from zooctl.errors import InputError, Terminated
from zooctl.executors import get_executor
from zooctl.pipelines.batch import BatchInterrupted, BatchItem, Progress, run_batch
from zooctl.pipelines.batch_fit import commit_fit, fit_task, plan_fits, skip_finished

pytestmark = pytest.mark.usefixtures("one_thread")


def flaky(item, report):
    """Dies (the whole worker process) on its first attempt when asked to; bad input on 'bad'."""
    marker, kind = item
    report("working")
    if kind == "bad":
        raise InputError("this item is bad", hint="fix it")
    if kind == "die" and not marker.exists():
        marker.write_text("died once")
        os._exit(3)
    return {"pid": os.getpid(), "kind": kind}


def holds_scratch(folder, report):
    """Makes a scratch folder, says so, and waits with it (removed in `finally`, as fit_task's)."""
    try:
        folder.mkdir()
        report("working")
        time.sleep(120)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def holds_scratch_with_pid(folder, report):
    """`holds_scratch`, leaving its process id beside the folder."""
    folder.with_suffix(".pid").write_text(str(os.getpid()))
    holds_scratch(folder, report)


def cleans_up_slowly(item, report):
    """Holds ``folder`` until ended, then takes a second to clean up, logging when it has; a task
    tried again returns at once."""
    folder, log = item
    if folder.with_suffix(".pid").exists():
        return None
    folder.with_suffix(".pid").write_text(str(os.getpid()))
    try:
        folder.mkdir()
        report("working")
        time.sleep(120)
    finally:
        time.sleep(1)
        shutil.rmtree(folder, ignore_errors=True)
        with log.open("a") as f:
            f.write(f"cleaned {os.getpid()}\n")


def test_pool_retries_a_dead_worker_and_reports_bad_input(tmp_path):
    items = [
        BatchItem(f"i{k}", (tmp_path / f"m{k}", kind)) for k, kind in enumerate(["ok", "die", "bad", "ok"])
    ]
    stages = []

    class Rec(Progress):
        def stage(self, key, stage):
            stages.append((key, stage))

    ex = get_executor("local", jobs=2)
    committed = []
    report = run_batch(ex, flaky, items, lambda it, v: committed.append(it.key) or v, progress=Rec())
    by = {r.key: r for r in report.results}
    assert [r.key for r in report.results] == ["i0", "i1", "i2", "i3"]
    assert by["i1"].status == "done" and by["i1"].attempts >= 2  # its worker died once
    # Bad input is never retried for its own error; a pool that loses a worker fails every task in
    # flight (Python's ProcessPoolExecutor), so i2 may have run once more if it ran beside i1's death.
    assert by["i2"].status == "failed" and by["i2"].error == "this item is bad" and by["i2"].attempts <= 2
    assert sorted(committed) == ["i0", "i1", "i3"]  # each good result committed exactly once
    assert ("i0", "working") in stages


def test_local_jobs2_fits_each_video_once_then_resume_skips_them(tmp_path, store):
    videos = fit_inputs(tmp_path, store, 3)
    items = plan_fits(videos + [videos[0]], store, tiny_config(), template="a0", out_root=tmp_path / "out")
    assert [it.key for it in items] == ["a0", "a1", "a2", "a0-2"]  # a repeated input gets its own name
    report = run_batch(get_executor("local", jobs=2), fit_task, items, commit_fit)
    assert report.count("done") == 4, report.to_json()
    recs = fit_records(store)
    assert sorted(recs) == ["a0", "a0-2", "a1", "a2"] and all(r["status"] == "done" for r in recs.values())
    # Outputs moved from the worker's private folder to OUT/NAME, and the records say so.
    fit_json = json.loads((tmp_path / "out" / "a1" / "fit.json").read_text())
    assert fit_json["out"] == str((tmp_path / "out" / "a1").resolve())
    assert Path(recs["a1"]["outputs"]["usd"]).is_file() and (store / "fits" / "a1" / "character.h5").is_file()
    assert not temporaries(store)
    again = run_batch(get_executor("local", jobs=2), fit_task, items, commit_fit, skip=skip_finished)
    assert again.count("skipped") == 4 and again.count("done") == 0


def test_a_fit_task_removes_the_scratch_folders_of_workers_killed_before_it(tmp_path, store, monkeypatch):
    import tempfile

    from test_worker_scratch import claimed_by_a_process_that_dies

    scratch_root = tmp_path / "tmp"
    scratch_root.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(scratch_root))
    dead = claimed_by_a_process_that_dies(scratch_root, "kill")  # as the OOM killer leaves one
    videos = fit_inputs(tmp_path, store, 1)
    items = plan_fits(videos, store, tiny_config(), template="a0", out_root=tmp_path / "out")
    assert run_batch(get_executor("local"), fit_task, items, commit_fit).count("done") == 1
    assert not dead.exists() and not list(scratch_root.glob("zooctl-fit-*"))  # its own removed too


def test_interrupted_batch_resumes_and_stores_every_fit_once(tmp_path, store):
    videos = fit_inputs(tmp_path, store, 3)
    items = plan_fits(videos, store, tiny_config(), template="a0", out_root=tmp_path / "out")

    class CtrlC(Progress):  # the user presses Ctrl-C once the first fit is stored
        def finished(self, result):
            raise KeyboardInterrupt

    with pytest.raises(BatchInterrupted) as exc:
        run_batch(get_executor("local"), fit_task, items, commit_fit, progress=CtrlC())
    assert [r.status for r in exc.value.report.results] == ["done"]
    assert sorted(fit_records(store)) == ["a0"]
    assert stop_code(exc.value) == 130
    mtime = (store / "fits" / "a0" / "record.json").stat().st_mtime_ns
    report = run_batch(get_executor("local"), fit_task, items, commit_fit, skip=skip_finished)
    assert [r.status for r in report.results] == ["skipped", "done", "done"]
    assert sorted(fit_records(store)) == ["a0", "a1", "a2"]
    assert (store / "fits" / "a0" / "record.json").stat().st_mtime_ns == mtime  # not written again


def test_cli_fit_batch_lists_failures_and_bank_add_batch(tmp_path, store):
    videos = fit_inputs(tmp_path, store, 2)
    cfg = tmp_path / "tiny.json"
    cfg.write_text(json.dumps(tiny_config()))
    r = zooctl(
        "fit", *videos, "no-such-video", "--template", "a0", "--config", str(cfg),
        "--executor", "local", "--out", str(tmp_path / "out"), "--json", store=store,
    )  # fmt: skip
    assert r.code == 2 and "1 of 3 fits failed" in r.err
    rep = r.json()
    assert [(i["key"], i["status"]) for i in rep["items"]] == [
        ("a0", "done"),
        ("a1", "done"),
        ("no-such-video", "failed"),
    ]
    assert "neither a file or folder nor a stored video" in rep["items"][2]["error"]
    glbs = glb_files(tmp_path, 2)
    r = zooctl(
        "bank",
        "add",
        *map(str, glbs),
        str(tmp_path / "missing.glb"),
        "--executor",
        "local",
        "--jobs",
        "2",
        store=store,
    )
    assert r.code == 2 and "2 assets done" in r.out and "does not exist" in r.out
    r = zooctl("bank", "add", *map(str, glbs), "--resume", "--json", store=store)
    assert r.code == 0 and [i["status"] for i in r.json()["items"]] == ["skipped", "skipped"]
    r = zooctl("bank", "reindex", "m0", "m1", "nosuch", "--executor", "local", "--embedder", "silhouette",
               "--views", "4", "--size", "48", "--json", store=store)  # fmt: skip
    assert r.code == 2 and [i["status"] for i in r.json()["items"]] == ["done", "done", "failed"]
    assert r.json()["items"][0]["views"] == 4 and r.json()["items"][0]["embedders"] == ["silhouette"]
    r = zooctl("fit", str(tmp_path / "nowhere" / "*.mp4"), store=store)
    assert r.code == 2 and "no file matches" in r.err
    r = zooctl("fit", *videos, "--executor", "nope", store=store)
    assert r.code == 2 and "no executor named 'nope'" in r.err and "Traceback" not in r.err


def test_a_video_folder_is_decoded_in_the_worker_and_stored_once_by_the_driver(tmp_path, store):
    """A DAVIS folder: the worker decodes it and computes its flow; the driver stores the video,
    and the next batch fits the stored video instead of decoding the folder again."""
    import numpy as np
    from fit_helpers import write_davis_folder

    from zooctl.fit.inputs import load_bench_video
    from zooctl.store.videos import VideoStore

    videos = fit_inputs(tmp_path, store, 1)
    bench = load_bench_video(Path(videos[0]))
    folder = write_davis_folder(tmp_path / "tubecam", bench.frames, bench.masks)
    items = plan_fits([str(folder)], store, tiny_config(), template="a0", out_root=tmp_path / "out")
    assert items[0].key == "tubecam" and items[0].payload.ingest is not None
    report = run_batch(get_executor("local"), fit_task, items, commit_fit)
    assert report.count("done") == 1, report.to_json()
    vs = VideoStore(store)
    assert vs.names() == ["tubecam"] and fit_records(store)["tubecam"]["stored_video"] == "tubecam"
    assert np.array_equal(vs.get("tubecam").masks, bench.masks)
    again = plan_fits([str(folder)], store, tiny_config(), template="a0", out_root=tmp_path / "out")
    assert again[0].payload.ingest is None and again[0].payload.source == "tubecam"  # reused


def test_a_batch_worker_streams_the_video_it_decodes(tmp_path, store, monkeypatch):
    """Under an array read limit of half the video's arrays, the worker's decode, fit and the
    driver's store of the video still succeed: nothing holds the whole video in memory (the
    worker sends the compressed file, not its arrays)."""
    from fit_helpers import write_davis_folder

    from zooctl.fit.inputs import load_bench_video
    from zooctl.store.videos import VideoStore

    videos = fit_inputs(tmp_path, store, 1)
    bench = load_bench_video(Path(videos[0]))
    folder = write_davis_folder(tmp_path / "tubecam", bench.frames, bench.masks)
    T, H, W = bench.masks.shape
    arrays = T * H * W * 4 + 2 * (T - 1) * H * W * 5  # frames, masks; float16 flows, occlusions
    monkeypatch.setenv("ZOOCTL_MAX_ARRAY_MB", str(arrays / 2 / 2**20))
    items = plan_fits([str(folder)], store, tiny_config(), template="a0", out_root=tmp_path / "out")
    report = run_batch(get_executor("local"), fit_task, items, commit_fit)
    assert report.count("done") == 1, report.to_json()
    assert VideoStore(store).summary("tubecam")["frames"] == T


def test_a_video_stored_by_another_fit_during_the_batch_is_reused_or_kept(tmp_path, store):
    """While a batch's worker decodes a folder, `zooctl fit` of the same folder stores it: the
    driver reuses it. Had a different video taken the planned name, it stays, and the batch's
    video is stored beside it with its fit naming it."""
    from fit_helpers import write_davis_folder

    from zooctl.fit.inputs import load_bench_video
    from zooctl.fit.job import store_video
    from zooctl.store.videos import VideoStore

    videos = fit_inputs(tmp_path, store, 1)
    bench = load_bench_video(Path(videos[0]))
    folder = write_davis_folder(tmp_path / "a" / "tubecam", bench.frames, bench.masks)
    other = write_davis_folder(tmp_path / "b" / "tubecam", bench.frames[::-1], bench.masks[::-1])
    vs = VideoStore(store)

    items = plan_fits([str(folder)], store, tiny_config(), template="a0", out_root=tmp_path / "out")
    assert items[0].payload.ingest is not None and items[0].payload.ingest.name == "tubecam"
    assert store_video(Path(folder), store, None) == "tubecam"  # the other fit, faster
    report = run_batch(get_executor("local"), fit_task, items, commit_fit)
    assert report.count("done") == 1, report.to_json()
    assert vs.names() == ["tubecam"] and fit_records(store)["tubecam"]["stored_video"] == "tubecam"

    vs.remove("tubecam")
    # the fit tubecam exists now: a batch refuses the name (the old fit untouched) unless --replace
    again = plan_fits([str(folder)], store, tiny_config(), template="a0", out_root=tmp_path / "out2")
    assert again[0].error is not None and "--replace" in again[0].error.hint
    items = plan_fits(
        [str(folder)], store, tiny_config(), template="a0", out_root=tmp_path / "out2", keep_existing=False
    )
    assert store_video(Path(other), store, None) == "tubecam"  # another file of the same name
    report = run_batch(get_executor("local"), fit_task, items, commit_fit)
    assert report.count("done") == 1, report.to_json()
    assert vs.names() == ["tubecam", "tubecam-2"]
    assert vs.get("tubecam").source["path"] == str(Path(other).resolve())  # untouched
    assert vs.get("tubecam-2").source["path"] == str(Path(folder).resolve())
    rec = fit_records(store)["tubecam"]
    assert rec["stored_video"] == rec["video"] == rec["source"] == "tubecam-2"
    fit_json = json.loads((tmp_path / "out2" / "tubecam" / "fit.json").read_text())
    assert fit_json["stored_video"] == "tubecam-2"


def test_a_renamed_video_is_renamed_in_the_notes_commands_too():
    """The close-trials note tells the user `zooctl fit NAME --template X`: after the driver
    stored the batch's video as NAME-2, the command must name NAME-2 (NAME is another video)."""
    from zooctl.fit.template import close_trials_note
    from zooctl.pipelines.batch_fit import _renamed_video

    tried = [{"name": "wolf", "trial_iou": 0.80}, {"name": "fox", "trial_iou": 0.795}]
    note = close_trials_note(tried, "wolf", "tubecam")
    rec = {"source": "tubecam", "video": "tubecam", "stored_video": "tubecam", "notes": [note, "tubecam x"]}
    out = _renamed_video(rec, "tubecam", "tubecam-2")
    assert "`zooctl fit tubecam-2 --template fox`" in out["notes"][0]
    assert "zooctl fit tubecam " not in out["notes"][0] and out["notes"][1] == "tubecam x"
    assert out["source"] == out["video"] == out["stored_video"] == "tubecam-2"
    assert rec["notes"][0] == note  # the worker's record is not changed in place


def test_bench_run_on_an_executor_keeps_the_row_order_and_resumes(tmp_path, store):
    from fit_helpers import tiny_overrides

    from zooctl.benchdata.run import run_benchmark

    fit_inputs(tmp_path, store, 2)
    folder = tmp_path / "videos"
    kw = {"ablations": ["full", "no-flow"], "template": "a0", "overrides": tiny_overrides()}
    res = run_benchmark(folder, store, executor=get_executor("local", jobs=2), **kw)
    assert [(r["video"], r["ablation"]) for r in res["rows"]] == [
        ("a0", "full"), ("a1", "full"), ("a0", "no-flow"), ("a1", "no-flow"),
    ]  # fmt: skip
    assert all("error" not in r and 0 <= r["mask_iou"] <= 1 for r in res["rows"]), res["rows"]
    assert sorted(fit_records(store)) == [
        "bench-a0-full",
        "bench-a0-no-flow",
        "bench-a1-full",
        "bench-a1-no-flow",
    ]
    again = run_benchmark(folder, store, executor=get_executor("local"), resume=True, **kw)
    assert [r["mask_iou"] for r in again["rows"]] == [r["mask_iou"] for r in res["rows"]]  # from the records


def test_a_batch_stopped_by_sigterm_exits_143(tmp_path, store):
    """SIGTERM (`zooctl.errors.Terminated`) stops a batch as Ctrl-C does, with its own code."""
    videos = fit_inputs(tmp_path, store, 2)
    items = plan_fits(videos, store, tiny_config(), template="a0", out_root=tmp_path / "out")

    class Term(Progress):
        def finished(self, result):
            raise Terminated

    with pytest.raises(BatchInterrupted) as exc:
        run_batch(get_executor("local"), fit_task, items, commit_fit, progress=Term())
    assert [r.status for r in exc.value.report.results] == ["done"] and stop_code(exc.value) == 143


def test_workers_ended_by_the_driver_remove_their_scratch_folders(tmp_path):
    """On Ctrl-C or SIGTERM the driver ends its workers with SIGTERM; a running task unwinds."""
    folders = [tmp_path / "a", tmp_path / "b"]
    working = set()

    def on_stage(i, stage):
        working.add(i)
        if len(working) == 2:
            raise KeyboardInterrupt

    ex = get_executor("local", jobs=2)
    with pytest.raises(KeyboardInterrupt):
        list(ex.map(holds_scratch, folders, on_stage))
    assert not any(f.exists() for f in folders)


@pytest.mark.skipif(
    not sys.platform.startswith("linux"), reason="the workers' end with the driver uses Linux's prctl"
)
def test_workers_of_a_killed_driver_end_and_remove_their_scratch_folders(tmp_path):
    """A driver killed outright (SIGKILL: no handler runs) takes its workers with it: they do not
    go on working for nobody, and their tasks unwind."""
    folders = [tmp_path / "a", tmp_path / "b"]
    driver = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys; from pathlib import Path; sys.path.insert(0, sys.argv[1]);"
            f"from test_batch_local import {holds_scratch_with_pid.__name__} as task;"
            "from zooctl.executors import get_executor;"
            "list(get_executor('local', jobs=2).map(task, [Path(p) for p in sys.argv[2:]]))",
            str(Path(__file__).parent),
            *map(str, folders),
        ]
    )
    try:
        deadline = time.monotonic() + 120
        while not all(f.with_suffix(".pid").exists() and f.exists() for f in folders):
            assert time.monotonic() < deadline and driver.poll() is None, "the workers never started"
            time.sleep(0.2)
    finally:
        driver.kill()
        driver.wait()
    pids = [int(f.with_suffix(".pid").read_text()) for f in folders]
    deadline = time.monotonic() + 30
    while any(f.exists() for f in folders) or any(_alive(p) for p in pids):
        assert time.monotonic() < deadline, "the workers outlived their driver"
        time.sleep(0.2)


def test_a_second_sigterm_does_not_cut_a_task_s_cleanup_short(tmp_path):
    """Linux sends the parent-death signal once for each driver thread that ends holding the worker,
    so a killed driver's workers can get SIGTERM twice in quick succession. The first unwinds the
    task; the second must neither cut its cleanup short nor leave the worker waiting for work."""
    folders, log = [tmp_path / "a", tmp_path / "b"], tmp_path / "cleaned.log"
    driver = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys; from pathlib import Path; sys.path.insert(0, sys.argv[1]);"
            f"from test_batch_local import {cleans_up_slowly.__name__} as task;"
            "from zooctl.executors import get_executor;"
            "log = Path(sys.argv[2]); items = [(Path(p), log) for p in sys.argv[3:]];"
            "print([o.error for o in get_executor('local', jobs=2).map(task, items)])",
            str(Path(__file__).parent),
            str(log),
            *map(str, folders),
        ]
    )
    try:
        deadline = time.monotonic() + 120
        while not all(f.exists() for f in folders):
            assert time.monotonic() < deadline and driver.poll() is None, "the workers never started"
            time.sleep(0.2)
        pid = int(folders[0].with_suffix(".pid").read_text())
        os.kill(pid, signal.SIGTERM)
        time.sleep(0.3)  # inside the task's cleanup, which takes a second
        with contextlib.suppress(ProcessLookupError):  # a machine so slow that the worker is gone
            os.kill(pid, signal.SIGTERM)
        deadline = time.monotonic() + 30
        while _alive(pid):
            assert time.monotonic() < deadline, "a worker whose task was ended went on living"
            time.sleep(0.2)
        assert f"cleaned {pid}" in log.read_text().split("\n")
    finally:
        driver.kill()
        driver.wait()


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return Path(f"/proc/{pid}/stat").exists() and Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"


def test_gpu_places_fill_every_gpu_in_turn():
    from zooctl.errors import UsageError
    from zooctl.executors.local import gpu_places

    assert gpu_places(0.25, ["0"]) == ["0"] * 4
    assert gpu_places(0.3, ["0"]) == ["0"] * 3
    assert gpu_places(0.5, ["0", "1"]) == ["0", "1", "0", "1"]
    assert gpu_places(1, ["3", "5"]) == ["3", "5"]
    assert gpu_places(2, ["0", "1", "2", "3", "4"]) == ["0,1", "2,3"]
    assert gpu_places(1, ["0", "1"], jobs=3) == ["0", "1", "0"]
    assert gpu_places(1, []) == [] and gpu_places(0, ["0"]) == []
    with pytest.raises(UsageError, match="more GPUs than the 1 this machine has"):
        gpu_places(2, ["0"])


def test_fits_share_a_gpu_by_default_as_far_as_the_host_s_cores_go(monkeypatch):
    from zooctl.cli import batch_opts
    from zooctl.cli.batch_opts import BatchOptions, tasks_per_gpu
    from zooctl.executors import local

    assert tasks_per_gpu(4, 1.0, 1, 16) == 4
    assert tasks_per_gpu(4, 1.0, 1, 2) == 2  # one fit a host core
    assert tasks_per_gpu(4, 1.0, 8, 16) == 2
    assert tasks_per_gpu(4, 3.0, 1, 2) == 1
    monkeypatch.setattr(local, "visible_gpus", lambda: ["0"])
    monkeypatch.setattr(batch_opts, "usable_cores", lambda: 16)
    assert BatchOptions().make_executor("cuda", fits=9).gpus == 0.25
    assert BatchOptions(cpus=8.0).make_executor("cuda", fits=9).gpus == 0.5
    assert BatchOptions().make_executor("cuda").gpus == 1.0  # other tasks: a GPU each
    assert BatchOptions(gpus=1.0).make_executor("cuda", fits=9).gpus == 1.0  # the user's word
    assert BatchOptions().make_executor("cuda:0", fits=9).gpus == 0.0
    assert local.gpu_places(BatchOptions().make_executor("cuda", fits=9).gpus, ["0"]) == ["0"] * 4


def test_fits_on_the_cpu_fill_the_cores_and_memory_by_default(monkeypatch):
    from zooctl.cli import batch_opts
    from zooctl.cli.batch_opts import BatchOptions, fits_at_once

    assert fits_at_once(28, 1.0, 2, 64.0) == 2
    assert fits_at_once(3, 1.0, 16, 64.0) == 3  # no more than there are videos
    assert fits_at_once(28, 1.0, 64, 30.0) == 20  # 1.5 GB a fit
    assert fits_at_once(28, 4.0, 16, None) == 4
    assert fits_at_once(28, 1.0, 8, 0.5) == 1
    monkeypatch.setattr(batch_opts, "usable_cores", lambda: 16)
    monkeypatch.setattr(batch_opts, "available_memory_gb", lambda: 64.0)
    ex = BatchOptions().make_executor("cpu", fits=28)
    assert (ex.jobs, ex.threads) == (16, 1)
    ex = BatchOptions().make_executor(None, fits=3)
    assert (ex.jobs, ex.threads) == (3, 5)  # the cores shared out: their trials side by side
    ex = BatchOptions(jobs=2).make_executor("cpu", fits=28)
    assert (ex.jobs, ex.threads) == (2, 8)
    ex = BatchOptions(cpus=1.0).make_executor("cpu", fits=3)
    assert (ex.jobs, ex.threads) == (3, 1)
    ex = BatchOptions(jobs=1, cpus=1.0).make_executor("cpu", fits=28)  # the user's word
    assert (ex.jobs, ex.threads) == (1, 1)
    ex = BatchOptions().make_executor("cpu")  # other tasks: one at a time, one core, as before
    assert (ex.jobs, ex.threads) == (None, 1)


def seen_gpus(item, report):
    return os.environ.get("CUDA_VISIBLE_DEVICES")


def test_each_local_worker_sees_the_gpu_it_is_placed_on(monkeypatch):
    import multiprocessing
    import signal

    from zooctl.executors import local

    monkeypatch.setattr(local, "visible_gpus", lambda: ["0", "1"])
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "0,1")
    ex = get_executor("local", gpus_per_task=0.5)
    assert ex.slots == 4 and ex.places == ["0", "1", "0", "1"]
    assert get_executor("local", gpus_per_task=1).slots == 2  # one task per GPU
    assert get_executor("local", gpus_per_task=0).slots == 1  # nothing asked: one after another
    from zooctl.cli.batch_opts import BatchOptions

    assert BatchOptions().make_executor("cuda").slots == 2  # --device cuda: a fit on each GPU
    assert BatchOptions().make_executor("cuda:1").places == []  # one GPU named: all on it
    assert BatchOptions(jobs=3).make_executor("cuda").places == ["0", "1", "0"]
    # the workers, one after another, as the pool starts them
    taken = multiprocessing.get_context("spawn").Value("i", 0)
    handler = signal.getsignal(signal.SIGTERM)
    seen = []
    try:
        for _ in range(5):
            local._init_worker(None, None, ex.places, taken)
            seen.append(os.environ["CUDA_VISIBLE_DEVICES"])
    finally:
        signal.signal(signal.SIGTERM, handler)
    assert seen == ["0", "1", "0", "1", "0"]
    # and through a real pool: every task runs on a worker placed on one of the two
    try:
        got = [o.value for o in ex.map(seen_gpus, list(range(4)))]
    finally:
        ex.close()
    assert len(got) == 4 and set(got) <= {"0", "1"}
