"""The built-in ``local`` executor: tasks in this process one after another, or in ``--jobs N``
worker processes on this machine.

Tasks that ask for GPUs (``--gpus-per-task``, 1 by default with ``--device cuda``) are placed on
the machine's GPUs: each worker sees its own through ``CUDA_VISIBLE_DEVICES``, set before its
first task imports torch. A fraction 1/k runs k workers on every GPU (small fits leave a GPU
waiting on Python and kernel launches, so several at once use it better), a whole number n gives
each worker n GPUs of its own; without ``--jobs`` there are as many workers as that fills.

Worker processes are started with ``spawn`` (a fresh interpreter: forking a process that has
torch's thread pools running is unsafe). A worker that dies (killed, out of memory) breaks
Python's pool; the pool is then rebuilt and the tasks that were running are retried, each such
event counting as an attempt of every task that was in flight. A worker sent SIGTERM (by the
driver ending its pool, by Linux when the driver dies, by hand) unwinds its running task, so the
task's cleanup runs whole, and exits: to the pool, a worker that died.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import signal
from collections.abc import Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from ..errors import Terminated, UsageError
from .base import ExecutorBase, StageCallback, Task, TaskOutcome, call_task, crashed, finished, retry_or_fail

_STAGES: Any = None  # the worker's end of the driver's stage queue (set by _init_worker)
_IN_TASK = False
_ENDING = False  # a SIGTERM is unwinding this worker's task: the worker goes once it has unwound
_DRIVER: int | None = None  # the driver's process id, where a worker ends with it (Linux)


def _on_sigterm(signum: int, frame: Any) -> None:
    # The driver ends its workers with SIGTERM on Ctrl-C or its own SIGTERM, and Linux sends one
    # when the driver dies, once for each driver thread that ends holding the worker. The first
    # unwinds a running task, so its `finally` removes its scratch folder; later ones must not cut
    # that short. An idle worker just goes.
    global _ENDING
    if not _IN_TASK:
        os._exit(128 + signum)
    if not _ENDING:
        _ENDING = True
        raise Terminated()


def _end_with_driver(driver: int) -> None:
    """Linux: SIGTERM this worker when the driver dies (SIGKILL, a crash), so that it does not fit on
    for nobody and its task unwinds as on the driver's own SIGTERM. Elsewhere a worker whose driver
    died outright finishes its task and then waits, idle, until it is killed."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(1, signal.SIGTERM, 0, 0, 0) != 0:  # PR_SET_PDEATHSIG
            return
    except (OSError, AttributeError):
        return
    if os.getppid() != driver:  # the driver died before the request was in place
        os._exit(128 + signal.SIGTERM)


def visible_gpus() -> list[str]:
    """The CUDA devices this process sees, named as a worker's ``CUDA_VISIBLE_DEVICES`` names them
    (the driver's own list when it set one, else their indices); [] without CUDA."""
    try:
        import torch

        count = torch.cuda.device_count()
    except Exception:  # a torch without CUDA, or no driver
        return []
    named = [d.strip() for d in os.environ.get("CUDA_VISIBLE_DEVICES", "").split(",") if d.strip()]
    return named[:count] if len(named) >= count else [str(i) for i in range(count)]


def gpu_places(gpus_per_task: float, devices: list[str], jobs: int | None = None) -> list[str]:
    """Each worker's ``CUDA_VISIBLE_DEVICES`` for tasks asking ``gpus_per_task`` GPUs each of
    ``devices``: a fraction 1/k (rounded down to it) puts k workers on every GPU, a whole number n
    (rounded up to it) gives each worker n GPUs of its own; ``jobs``, when given, is the number of
    workers, taking the GPUs in turn. [] when no GPU is asked for or none is there: the tasks then
    see what the driver sees, and a fit on ``cuda`` says that there is none."""
    if gpus_per_task <= 0 or not devices:
        return []
    if gpus_per_task < 1:
        groups, each = [[d] for d in devices], max(1, math.floor(1 / gpus_per_task + 1e-9))
    else:
        n = math.ceil(gpus_per_task - 1e-9)
        if n > len(devices):
            raise UsageError(
                f"--gpus-per-task {gpus_per_task:g} asks for more GPUs than the {len(devices)} this machine has",
                hint=f"give at most {len(devices)}, or a fraction such as 0.25 to run several tasks on one GPU",
            )
        groups, each = [devices[i : i + n] for i in range(0, len(devices) - n + 1, n)], 1
    order = [g for _ in range(each) for g in groups]  # the GPUs in turn: every one busy before any doubles up
    return [",".join(order[w % len(order)]) for w in range(jobs or len(order))]


def _init_worker(
    stages: Any, driver: int | None = None, places: list[str] | None = None, taken: Any = None
) -> None:
    global _STAGES, _DRIVER
    _STAGES, _DRIVER = stages, driver
    signal.signal(signal.SIGTERM, _on_sigterm)
    if places:  # before anything imports torch: CUDA reads it once
        with taken.get_lock():
            w, taken.value = taken.value, taken.value + 1
        os.environ["CUDA_VISIBLE_DEVICES"] = places[w % len(places)]
    if driver is not None:
        _end_with_driver(driver)


def _report_to_queue(index: int):
    def report(stage: str) -> None:
        try:
            _STAGES.put((index, stage))  # written before it returns: a worker killed later loses nothing
        except Exception:  # progress is a nicety, never a reason to fail a task
            pass

    return report


def _pool_task(fn: Task, item: Any, index: int, env: dict[str, str], threads: int):
    global _IN_TASK
    try:
        _IN_TASK = True  # inside the try: a SIGTERM right after it still reaches the exit below
        return call_task(fn, item, _report_to_queue(index), env, threads)
    finally:
        try:
            _IN_TASK = False
        finally:  # reached even where a SIGTERM lands on the line above
            # A task ended by SIGTERM: nobody waits for its result (the driver ends its pool, or is
            # gone while one of its threads still lives, so the parent's pid has not changed yet).
            # A driver gone: nobody reads the result, and the queue's write end, which every worker
            # holds too, never closes, so the pool's loop would wait for work forever.
            if _ENDING or (_DRIVER is not None and os.getppid() != _DRIVER):
                os._exit(128 + signal.SIGTERM)


class LocalExecutor(ExecutorBase):
    name = "local"

    def __init__(self, **options: Any) -> None:
        """Takes the `ExecutorOptions` fields; ``address`` is refused (no cluster here)."""
        super().__init__(**options)
        if self.address:
            raise UsageError("--address is for a cluster executor", hint="use --executor ray --address ...")
        # each worker's GPUs; one worker on one GPU runs in this process, which sees it already
        self.places = gpu_places(self.gpus, visible_gpus(), self.jobs) if self.gpus > 0 else []
        self.slots = len(self.places) or self.jobs or 1
        self._pool: ProcessPoolExecutor | None = None

    # -- sequential ----------------------------------------------------------------------
    def _map_inline(self, fn: Task, items: list[Any], on_stage: StageCallback | None):
        for i, item in enumerate(items):
            last = ""
            for attempt in range(1, self.retries + 2):

                def report(stage: str, _i: int = i) -> None:
                    if on_stage is not None:
                        on_stage(_i, stage)

                try:
                    result = call_task(fn, item, report, self.env, self.threads)
                except Exception as exc:  # a crash: retried, bounded
                    last = f"{type(exc).__name__}: {exc}"
                    continue
                yield finished(i, result, attempt)
                break
            else:
                yield crashed(i, self.retries + 1, last)

    # -- process pool ----------------------------------------------------------------------
    def _new_pool(self, stages: Any) -> ProcessPoolExecutor:
        ctx = multiprocessing.get_context("spawn")
        taken = ctx.Value("i", 0)  # workers started so far: the next one takes the next place
        return ProcessPoolExecutor(
            self.slots,
            mp_context=ctx,
            initializer=_init_worker,
            initargs=(stages, os.getpid(), self.places, taken),
        )

    def _map_pool(self, fn: Task, items: list[Any], on_stage: StageCallback | None):
        stages = multiprocessing.get_context("spawn").SimpleQueue()
        self._pool = self._new_pool(stages)
        todo = list(range(len(items)))[::-1]  # a stack: pop() takes the first item first
        attempts = [0] * len(items)
        running: dict[Future, int] = {}
        try:
            while todo or running:
                while todo and len(running) < self.slots:  # one task per worker: all in flight run
                    i = todo.pop()
                    attempts[i] += 1
                    fut = self._pool.submit(_pool_task, fn, items[i], i, self.env, self.threads)
                    running[fut] = i
                    _wake_manager(self._pool)
                done, _ = wait(list(running), timeout=0.25, return_when=FIRST_COMPLETED)
                _drain(stages, on_stage)
                broken = False
                for fut in done:
                    i = running.pop(fut)
                    try:
                        result = fut.result()
                    except BrokenProcessPool:
                        broken = True
                        failed = self._retry(i, "its worker process died", attempts, todo)
                    except Exception as exc:
                        failed = self._retry(i, f"{type(exc).__name__}: {exc}", attempts, todo)
                    else:
                        failed = finished(i, result, attempts[i])
                    if failed is not None:
                        yield failed
                if broken:  # the other tasks of the dead pool: keep what returned, retry the rest
                    for fut in list(running):
                        i = running.pop(fut)
                        if fut.done() and fut.exception() is None:
                            yield finished(i, fut.result(), attempts[i])
                            continue
                        failed = self._retry(i, "its worker pool lost a process", attempts, todo)
                        if failed is not None:
                            yield failed
                    self._pool.shutdown(wait=False, cancel_futures=True)
                    self._pool = self._new_pool(stages)
        finally:
            self._stop_pool()
            _drain(stages, on_stage)

    def _retry(self, i: int, reason: str, attempts: list[int], todo: list[int]) -> TaskOutcome | None:
        return retry_or_fail(i, reason, attempts, todo, self.retries)

    def _stop_pool(self) -> None:
        pool, self._pool = self._pool, None
        if pool is None:
            return
        # Python's pool cannot stop a running task: end its workers so Ctrl-C is prompt.
        for p in list(getattr(pool, "_processes", {}).values()):
            if p.is_alive():
                p.terminate()
        pool.shutdown(wait=True, cancel_futures=True)

    def map(self, fn: Task, items: list[Any], on_stage: StageCallback | None = None) -> Iterator[TaskOutcome]:
        if self.slots == 1:
            return self._map_inline(fn, list(items), on_stage)
        return self._map_pool(fn, list(items), on_stage)

    def close(self) -> None:
        self._stop_pool()


def _wake_manager(pool: ProcessPoolExecutor) -> None:
    """Wake the pool's manager thread once more after a submit. Python's pool (3.11) wakes it
    before it starts the worker that submit needs, so the manager can go on waiting on the workers
    it knew before and miss the new one's death until some other worker returns a result: a batch
    whose last task's worker was killed waited forever."""
    wakeup, lock = (
        getattr(pool, "_executor_manager_thread_wakeup", None),
        getattr(pool, "_shutdown_lock", None),
    )
    if wakeup is None or lock is None:
        return
    with lock:
        if not getattr(wakeup, "_closed", False):
            wakeup.wakeup()


def _drain(stages: Any, on_stage: StageCallback | None) -> None:
    while True:
        try:
            if stages.empty():
                return
            i, stage = stages.get()
        except (EOFError, OSError, ValueError):
            return
        if on_stage is not None:
            on_stage(i, stage)
