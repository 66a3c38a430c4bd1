"""The template trials side by side: each candidate's short fit (or each of a named template's
two starts, `zooctl.fit.named_start.start_trial`) in its own process.

A trial is a fit of a few thousand vertices at a fit resolution of about a hundred pixels: too
small a job to keep more than one core busy through torch's own threads (on two cores a fit runs
at about 1.3 cores). The trials of different templates are independent, so on a CPU with two or
more torch threads they run at once, in worker processes that split the threads between them;
each trial's paused state comes back to continue the winner's fit exactly where it stopped.

``cfg.trials.workers`` sets how many processes (0: one per trial, while they are at most twice
the torch threads, else one per thread; 1: one after another in this process, as with a plugin
registered in this process alone). On CUDA the default (0) runs them one after another in this
process; a number of two or more runs that many processes side by side on the fit's GPU, each
with its own host core for the launches a step is bound by (not yet measured on a GPU:
BENCHMARKS.md, "The two starts side by side").
The trials are the same fits either way: side by side they agree with one after another within
float summation order (`torch` threads differ), not bit for bit.

Workers are forked from a fork server that has imported torch and the fit once (`_context`): a
spawned worker imports them again, about 2 s of CPU, and a fit with retrieval starts its trials'
workers twice (BENCHMARKS.md, "Trial workers forked from a server that has imported the fit").
The server's torch has run no operation, so no thread pool is copied into a worker, and each
worker takes on the parent's environment as it is when the trials start, as a spawned one would.
Where the platform has no fork server (Windows) they are spawned. Either way a script that calls
the fit guards its top level with ``if __name__ == "__main__":``, as for PyTorch's DataLoader
workers (without it, the pool breaks and the trials run one after another here).
"""

from __future__ import annotations

import io
import multiprocessing
import os
import queue as queue_mod
import threading
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from ..asset import RiggedAsset
    from .config import FitConfig
    from .inputs import FitVideo
    from .run import Reporter
    from .view_trial import TrialResult


@dataclass
class Trial:
    """One trial to run: ``asset``'s fit paused after ``pause_at`` stage-2 iterations, from the
    start (``state`` None; ``mirror``: with `trial_with_mirror`'s depth-mirror check; ``length``:
    the template's body made that much longer first; ``motion`` and ``track``: the fit's
    ``camera.motion`` and ``camera.track`` for this trial, when not None; ``then``: fitted on from
    that pause to this iteration and paused again) or on from a paused ``state``. ``label``
    names it in progress reports (default: its template's name); ``found``: a camera search
    already made (`fit_video`'s), not run again."""

    asset: RiggedAsset
    pause_at: int
    mirror: bool = False
    state: dict[str, Any] | None = None
    length: float = 1.0
    motion: str | None = None
    track: str | None = None
    then: int | None = None
    label: str | None = None
    found: dict[str, Any] | None = None

    @property
    def name(self) -> str:
        return self.label or self.asset.name


def trial_threads(cfg: FitConfig, n: int, threads: int | None = None) -> list[int]:
    """The torch threads of each of ``n`` trials run side by side, one process each, or [] to run
    them one after another in this process (module docstring). ``threads``: the torch threads
    this process has (default ``torch.get_num_threads()``), shared out as evenly as they go, at
    least one each."""
    import torch

    threads = torch.get_num_threads() if threads is None else threads
    workers = cfg.trials.workers
    cuda = str(cfg.device).startswith("cuda")
    if n < 2 or workers == 1 or (cuda and workers == 0) or (threads < 2 and not cuda):
        return []
    if multiprocessing.current_process().daemon:  # a pool's worker may not start processes
        return []
    if _plugins_in_process():
        return []
    if workers == 0:
        # one process per trial: three trials on two cores finish together, where two processes
        # would leave one core idle while the third ran alone; many more trials than threads
        # take turns in one process per thread
        procs = n if n <= 2 * threads else threads
    else:
        procs = min(n, workers)
    return [max(1, threads // procs + (i < threads % procs)) for i in range(procs)]


def _plugins_in_process() -> bool:
    """Whether a plugin was registered in this process alone (a notebook's, an embedding
    application's): a spawned worker loads the installed plugins only, and would miss it."""
    from ..plugins import get_plugin_manager

    return bool(get_plugin_manager().in_process)


def run_trials(
    video: FitVideo,
    trials: list[Trial],
    cfg: FitConfig,
    reporter: Reporter | None = None,
    checkpoint: Callable[[dict[str, Any]], None] | None = None,
) -> list[TrialResult]:
    """Run ``trials`` (in this order, side by side where `trial_threads` says so) and return
    their results in the same order. A pool that breaks (a worker killed: out of memory, say)
    falls back to running them all here, one after another; a trial's own error is raised here
    as it was raised there. ``checkpoint`` saves the trials' states as they run here; side by
    side they save none (a fit stopped inside them runs them again)."""
    shares = trial_threads(cfg, len(trials))
    if not shares:
        return _one_by_one(video, trials, cfg, reporter, checkpoint)
    try:
        return _side_by_side(video, trials, cfg, reporter, shares)
    except BrokenProcessPool as exc:
        if reporter is not None:
            reporter.message(f"the trials' processes stopped ({exc}): running the trials one after another")
        return _one_by_one(video, trials, cfg, reporter, checkpoint)


def _one_by_one(
    video: FitVideo,
    trials: list[Trial],
    cfg: FitConfig,
    reporter: Reporter | None,
    checkpoint: Callable[[dict[str, Any]], None] | None = None,
) -> list[TrialResult]:
    out = []
    for i, t in enumerate(trials):
        if reporter is not None and len(trials) > 1:
            what = t.label if t.label else f"template {t.asset.name}"
            reporter.message(f"trial fit {i + 1}/{len(trials)}: {what}")
        out.append(_run(video, t, cfg, reporter, checkpoint))
    return out


def _run(
    video: FitVideo,
    trial: Trial,
    cfg: FitConfig,
    reporter: Reporter | None,
    checkpoint: Callable[[dict[str, Any]], None] | None = None,
) -> TrialResult:
    from .view_trial import continue_trial, trial_with_mirror

    start = time.perf_counter()
    if trial.motion is not None:
        cfg = cfg.with_camera_motion(trial.motion)
    if trial.track is not None:
        cfg = replace(cfg, camera=replace(cfg.camera, track=trial.track))
    if trial.state is None:
        res = trial_with_mirror(
            video,
            trial.asset,
            cfg,
            reporter,
            checkpoint,
            mirror=trial.mirror,
            pause_at=trial.pause_at,
            length=trial.length,
            found=trial.found,
        )
        if trial.then is not None and trial.then > trial.pause_at and res.state is not None:
            on = continue_trial(video, trial.asset, cfg, res.state, trial.then, reporter)
            res = replace(on, view=res.view)
    else:
        res = continue_trial(video, trial.asset, cfg, trial.state, trial.pause_at, reporter)
    return replace(res, seconds=time.perf_counter() - start)


def _side_by_side(
    video: FitVideo, trials: list[Trial], cfg: FitConfig, reporter: Reporter | None, shares: list[int]
) -> list[TrialResult]:
    ctx = _context()
    events = ctx.Queue()
    forward = _Forwarder(events, reporter, [t.name for t in trials])
    forward.start()
    pool = _worker_pool(ctx, len(shares), events)
    try:
        inputs = _pack((video, cfg))  # once: the same for every trial
        futures = [
            pool.submit(_trial_in_worker, i, inputs, _pack(t), shares[i % len(shares)])
            for i, t in enumerate(trials)
        ]
        # a trial's error is raised here as it was there (errors pickle whole: `ZooctlError`)
        return [_unpack(f.result()) for f in futures]
    except KeyboardInterrupt:
        # Ctrl-C reaches the workers too, a SIGTERM to this process alone does not: end them
        for p in list((getattr(pool, "_processes", None) or {}).values()):
            if p.is_alive():
                p.terminate()
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        forward.stop()


def _worker_pool(ctx: Any, workers: int, events: Any) -> ProcessPoolExecutor:
    """Trial workers from ``ctx`` (`_context`), each with this process's environment as it is now
    and ``events`` (a ``ctx.Queue``) for its progress."""
    return ProcessPoolExecutor(
        max_workers=workers, mp_context=ctx, initializer=_start_worker, initargs=(events, dict(os.environ))
    )


# What the fork server imports once for every worker it forks: the trial's code and, through it,
# torch and the fit (`zooctl.fit.run`).
PRELOAD = ["zooctl.fit.trial_pool", "zooctl.fit.view_trial"]


def _context() -> Any:
    """The trials' process context: the fork server, preloaded with `PRELOAD`, where the platform
    has one and it starts; else spawn. Not fork: the fit's own process has run torch, whose thread
    pools a forked copy would inherit broken. The preload takes effect when this process's fork
    server first starts (a server some other code started first forks without it, only slower)."""
    if "forkserver" in multiprocessing.get_all_start_methods():
        from multiprocessing import forkserver

        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(PRELOAD)
        try:
            forkserver.ensure_running()  # its socket: a temporary folder's path too long, say
            return ctx
        except OSError:
            pass
    return multiprocessing.get_context("spawn")


def _pack(obj: Any) -> bytes:
    # torch's own pickling: tensors travel as bytes, not as shared-memory handles the sender must outlive
    import torch

    buf = io.BytesIO()
    torch.save(obj, buf)
    return buf.getvalue()


def _unpack(data: bytes) -> Any:
    import torch

    return torch.load(io.BytesIO(data), weights_only=False)


# -- in the worker ------------------------------------------------------------------------
_EVENTS: Any = None


def _start_worker(events: Any, environ: dict[str, str]) -> None:
    global _EVENTS
    _EVENTS = events
    # a forked worker has the fork server's environment, from when the server started
    os.environ.clear()
    os.environ.update(environ)


def _trial_in_worker(index: int, inputs: bytes, trial: bytes, threads: int) -> bytes:
    import torch

    torch.set_num_threads(threads)
    video, cfg = _unpack(inputs)
    return _pack(_run(video, _unpack(trial), cfg, _QueueReporter(index, _EVENTS)))


class _QueueReporter:
    """A `Reporter` in a worker: what it is told goes to the parent's `_Forwarder`."""

    def __init__(self, index: int, events: Any) -> None:
        self.index, self.events = index, events

    def stage(self, name: str, total: int, done: int = 0) -> None:
        self.events.put((self.index, "stage", (name, total, done)))

    def step(self, terms: dict[str, float]) -> None:
        self.events.put((self.index, "step", {k: float(v) for k, v in terms.items()}))

    def message(self, text: str) -> None:
        self.events.put((self.index, "message", text))


# -- in the parent ------------------------------------------------------------------------
class _Forwarder:
    """Passes the workers' reports on to ``reporter`` from a thread: every message, named by its
    template, and the stages and steps of one trial at a time (a reporter draws one bar). When the
    shown trial's stage is over, the bar goes to the next trial in turn that is inside a stage,
    from where that stage has got to, so every trial's progress shows."""

    def __init__(self, events: Any, reporter: Reporter | None, names: list[str]) -> None:
        self.events, self.reporter, self.names = events, reporter, names
        self.shown: int | None = None
        self.stages: dict[int, list] = {}  # trial -> [stage name, total steps, steps done]
        self.thread = threading.Thread(target=self._loop, name="zooctl-trial-reports", daemon=True)
        self.done = threading.Event()

    def start(self) -> None:
        self.thread.start()

    def stop(self) -> None:
        self.done.set()
        self.thread.join()

    def _loop(self) -> None:
        while True:
            try:
                index, kind, value = self.events.get(timeout=0.1)
            except queue_mod.Empty:
                if self.done.is_set():
                    return
                continue
            except (EOFError, OSError):
                return
            if self.reporter is not None:
                self._pass(index, kind, value)

    def _pass(self, index: int, kind: str, value: Any) -> None:
        rep = self.reporter
        assert rep is not None
        if kind == "message":
            rep.message(f"[{self.names[index]}] {value}")
        elif kind == "stage":
            name, total, done = value
            self.stages[index] = [name, total, done]
            if self.shown is None or self.shown == index:
                self._show(index)
        elif kind == "step":
            stage = self.stages.get(index)
            if stage is not None:
                stage[2] += 1
            if self.shown == index:
                rep.step(value)
                if stage is None or stage[2] >= stage[1]:
                    self._hand_on(index)

    def _show(self, index: int) -> None:
        name, total, done = self.stages[index]
        self.shown = index
        assert self.reporter is not None
        self.reporter.stage(f"{name} ({self.names[index]})", total, done)

    def _hand_on(self, index: int) -> None:
        """The bar of a trial whose stage is over, to the next trial after it inside a stage."""
        n = len(self.names)
        for k in range(1, n + 1):
            other = (index + k) % n
            stage = self.stages.get(other)
            if other != index and stage is not None and stage[2] < stage[1]:
                self._show(other)
                return
        self.shown = None  # the next trial to start a stage takes the bar
