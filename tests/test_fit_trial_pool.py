"""The template trials side by side, one process each (`zooctl.fit.trial_pool`)."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest
import torch
from test_fit_trials import TINY, _bank_with_views

from zooctl.benchdata.make import make_video
from zooctl.errors import InputError
from zooctl.fit import trial_pool
from zooctl.fit.config import FitConfig
from zooctl.fit.trial_pool import Trial, run_trials, trial_threads


def _cfg(**trials) -> FitConfig:
    return FitConfig.from_dict(
        {**json.loads(json.dumps(TINY)), "trials": {"candidates": 2, "iters": 2, **trials}}
    )


@contextlib.contextmanager
def _threads(n: int):
    old = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(old)


class _Recorder:
    def __init__(self) -> None:
        self.stages: list[str] = []
        self.steps = 0
        self.messages: list[str] = []

    def stage(self, name: str, total: int, done: int = 0) -> None:
        self.stages.append(name)

    def step(self, terms: dict[str, float]) -> None:
        self.steps += 1

    def message(self, text: str) -> None:
        self.messages.append(text)


def test_the_threads_are_shared_out_between_the_trials():
    cfg = _cfg()
    assert trial_threads(cfg, 3, threads=2) == [1, 1, 1]  # all at once: none runs alone at the end
    assert trial_threads(cfg, 6, threads=2) == [1, 1]  # many: they take turns, one process a thread
    assert trial_threads(cfg, 3, threads=8) == [3, 3, 2]
    assert trial_threads(cfg, 2, threads=16) == [8, 8]
    assert trial_threads(_cfg(workers=2), 3, threads=8) == [4, 4]
    assert trial_threads(cfg, 3, threads=1) == []  # one thread: one after another here
    assert trial_threads(cfg, 1, threads=8) == []
    assert trial_threads(_cfg(workers=1), 3, threads=8) == []
    cuda = dataclasses.replace(cfg, device="cuda")
    assert trial_threads(cuda, 3, threads=8) == []  # by default one after another on the device
    cuda_sbs = dataclasses.replace(_cfg(workers=3), device="cuda:1")
    assert trial_threads(cuda_sbs, 3, threads=8) == [3, 3, 2]  # asked for: side by side on the GPU
    assert trial_threads(cuda_sbs, 6, threads=1) == [1, 1, 1]  # each its own host core for launches
    assert trial_threads(dataclasses.replace(cuda_sbs, device="cpu"), 3, threads=1) == []


def test_a_plugin_registered_in_this_process_keeps_the_trials_here(monkeypatch):
    """A spawned worker loads the installed plugins only: a renderer a notebook registered would
    be missing there, so the trials stay in the process that has it."""
    from zooctl import plugins

    pm = plugins.PluginManager()
    pm.load_entry_points()
    monkeypatch.setattr(plugins, "_MANAGER", pm)
    assert trial_threads(_cfg(), 2, threads=2) == [1, 1]

    class Nothing:
        pass

    pm.register(Nothing(), "notebook-plugin")
    assert trial_threads(_cfg(), 2, threads=2) == []


def test_trials_side_by_side_are_the_trials_one_after_another(tmp_path, store):
    """Two processes of one thread each pick the same template, with the same trial IoUs and the
    same paused state, as the trials run here one after another on one thread."""
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.template import try_candidates

    bank, thin = _bank_with_views(store)
    video = load_fit_video(make_video(thin, tmp_path / "v", frames=3, size=32, seed=0))
    runs = []
    for threads, cfg in ((1, _cfg()), (2, _cfg())):
        assert bool(trial_threads(cfg, 2, threads=threads)) == (threads == 2)
        cands = [{"name": "fat", "score": -2.0}, {"name": "thin", "score": -1.0}]
        rep = _Recorder()
        with _threads(threads):
            runs.append((*try_candidates(bank, video, cands, cfg, rep), rep))
    (a_one, out_one, st_one, _), (a_two, out_two, st_two, rep) = runs
    assert a_one.name == a_two.name == "thin"
    assert out_one[1]["trial_iou"] > out_one[0]["trial_iou"]
    for c1, c2 in zip(out_one, out_two, strict=True):
        assert c1["trial_iou"] == pytest.approx(c2["trial_iou"], abs=1e-4)
        assert c1["view_trial"] == c2["view_trial"]
    assert st_two["iteration"] == st_one["iteration"] == 2
    for k, v in st_one["scene"].items():
        assert torch.allclose(v, st_two["scene"][k], atol=1e-5), k
    # the workers' reports reach the parent's reporter, named by template
    assert any(m.startswith("[fat] ") for m in rep.messages) or any("(fat)" in s for s in rep.stages)
    assert rep.stages and rep.steps > 0


def test_pruned_trials_side_by_side(tmp_path, store):
    """With a checkpoint, the trials run side by side to it and the kept one goes on from its own
    paused state, in a worker too."""
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.template import try_candidates

    bank, thin = _bank_with_views(store)
    video = load_fit_video(make_video(thin, tmp_path / "v", frames=3, size=32, seed=0))
    cands = [{"name": "fat", "score": -2.0}, {"name": "thin", "score": -1.0}]
    with _threads(2):
        asset, out, state = try_candidates(bank, video, cands, _cfg(prune_at=1, prune_margin=0.0))
    assert asset.name == "thin"
    assert out[0]["pruned_at"] == 1 and "pruned_at" not in out[1]
    assert state["iteration"] == 2 and len(state["history"]["stage2"]) == 2


def test_a_trials_error_reaches_the_caller_as_it_was_raised(tmp_path, store):
    from zooctl.fit.inputs import load_fit_video

    bank, thin = _bank_with_views(store)
    video = load_fit_video(make_video(thin, tmp_path / "v", frames=3, size=32, seed=0))
    bad = dataclasses.replace(thin, name="flat", faces=np.zeros((1, 3), np.int32))
    with _threads(2), pytest.raises(InputError, match="'flat' has too few faces"):
        run_trials(video, [Trial(thin, 1), Trial(bad, 1)], _cfg())


_STOPPED_SCRIPT = r"""
import signal, sys, torch
from zooctl.cli.main import _on_sigterm
from zooctl.errors import Terminated
from zooctl.benchdata.make import make_video
from zooctl.fit.config import FitConfig
from zooctl.fit.inputs import load_fit_video
from zooctl.fit.trial_pool import Trial, run_trials
from zooctl.rig.synthetic import tube_asset

class Say:
    def stage(self, name, total, done=0):
        print("stage", name, flush=True)
    def step(self, terms):
        pass
    def message(self, text):
        pass

if __name__ == "__main__":
    signal.signal(signal.SIGTERM, _on_sigterm)
    torch.set_num_threads(2)
    thin = tube_asset(bones=3, name="thin")
    fat = tube_asset(bones=2, bone_length=0.5, radius=0.6, name="fat")
    video = load_fit_video(make_video(thin, sys.argv[1], frames=3, size=32, seed=0))
    cfg = FitConfig.from_dict({"fit_size": 32, "stage1": {"iters": 2, "batch": 3},
        "stage2": {"iters": 100000, "batch": 3}, "camera": {"azimuths": 4, "elevations": [10.0], "search_size": 32}})
    try:
        run_trials(video, [Trial(thin, 100000), Trial(fat, 100000)], cfg, Say())
    except Terminated:
        print("terminated", flush=True)
        sys.exit(143)
"""


def _descendants(pid: int) -> list[int]:
    """The processes under ``pid`` (Linux's /proc), children first."""
    try:
        kids = [int(p) for p in open(f"/proc/{pid}/task/{pid}/children").read().split()]
    except FileNotFoundError:
        return []
    return kids + [d for k in kids for d in _descendants(k)]


def test_sigterm_during_the_trials_ends_their_processes(tmp_path):
    """A SIGTERM to the fit's process alone (a scheduler's cancel) does not reach the trials'
    workers: the pool ends them, and the fit stops at once instead of waiting for the trials."""
    import signal
    import subprocess
    import sys
    import time

    script = tmp_path / "stopped.py"
    script.write_text(_STOPPED_SCRIPT)
    proc = subprocess.Popen(
        [sys.executable, str(script), str(tmp_path / "v")], stdout=subprocess.PIPE, text=True
    )
    children: list[int] = []
    ended = False
    try:
        assert proc.stdout is not None
        for line in proc.stdout:  # a worker's trial reached stage 2: the pool is up
            if line.startswith("stage stage2"):
                break
        children += _descendants(proc.pid)  # the fork server's workers are its children, not the fit's
        assert len(children) >= 2, "the trials run in worker processes"
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=60) == 143

        def running(pid: int) -> bool:
            with contextlib.suppress(ProcessLookupError, ChildProcessError):
                os.waitpid(pid, os.WNOHANG)
            try:
                return "zombie" not in open(f"/proc/{pid}/status").read()
            except FileNotFoundError:
                return False

        deadline = time.monotonic() + 30  # the fork server finishes its interpreter's exit
        while any(running(pid) for pid in children) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not [pid for pid in children if running(pid)]
        ended = True
    finally:  # nothing left running when it fails
        for pid in [] if ended else [proc.pid, *children]:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        proc.wait()


@pytest.mark.skipif(
    "forkserver" not in multiprocessing.get_all_start_methods(), reason="this platform has no fork server"
)
def test_trial_workers_come_from_the_fork_server_with_this_process_environment(monkeypatch):
    """The workers are forked by the server that imported the fit once (their parent is not this
    process, as a spawned worker's is), and each sees the environment as it is when its trials
    start, not as it was when the server started."""
    ctx = trial_pool._context()
    assert ctx.get_start_method() == "forkserver"

    def pool() -> ProcessPoolExecutor:
        return trial_pool._worker_pool(ctx, 1, ctx.Queue())

    monkeypatch.setenv("ZOOCTL_TRIAL_ENV_CHECK", "before")
    with pool() as p:
        assert p.submit(os.getenv, "ZOOCTL_TRIAL_ENV_CHECK").result() == "before"
        assert p.submit(os.getppid).result() != os.getpid()
    monkeypatch.setenv("ZOOCTL_TRIAL_ENV_CHECK", "after")
    monkeypatch.delenv("HOME", raising=False)
    with pool() as p:
        assert p.submit(os.getenv, "ZOOCTL_TRIAL_ENV_CHECK").result() == "after"
        assert p.submit(os.getenv, "HOME").result() is None
