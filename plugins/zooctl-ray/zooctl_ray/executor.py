"""The ``ray`` executor: each item one Ray task, retried from the driver when it crashes or its
worker or node dies.

Retries are the driver's, not Ray's (``max_retries=0``): the driver then knows each item's
attempts, a crash and a lost node follow the same bound, and an item's result reaches the driver
(and so the store) once, whatever happened to the attempts that did not return.

The executor joins a running Ray (``--address``, ``RAY_ADDRESS``, or one this process started
already) or starts one on this machine sized for ``--jobs`` and stops it when the batch ends;
it connects when the first task is submitted.
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterator
from typing import Any

from zooctl.errors import MissingDependencyError, UsageError
from zooctl.executors.base import (
    ExecutorBase,
    StageCallback,
    Task,
    TaskOutcome,
    call_task,
    finished,
    retry_or_fail,
)

# Small by default: the results are files of a few MB, and the machine is shared.
OBJECT_STORE_MB = int(os.environ.get("ZOOCTL_RAY_OBJECT_STORE_MB", "300"))


def _ray():
    try:
        import ray
    except ImportError as exc:
        raise MissingDependencyError(
            f"the ray executor needs the `ray` package ({exc})", hint="pip install plugins/zooctl-ray"
        ) from None
    return ray


def _ray_task(fn: Task, item: Any, index: int, board: Any, env: dict[str, str], threads: int):
    def report(stage: str) -> None:
        if board is not None:
            board.set.remote(index, stage)  # fire and forget: progress never waits

    return call_task(fn, item, report, env, threads)


class _Board:
    """Each running item's latest stage; the driver drains it while it waits."""

    def __init__(self) -> None:
        self.stages: dict[int, str] = {}

    def set(self, index: int, stage: str) -> None:
        self.stages[index] = stage

    def drain(self) -> dict[int, str]:
        out, self.stages = self.stages, {}
        return out


class RayExecutor(ExecutorBase):
    name = "ray"

    def __init__(self, **options: Any) -> None:
        """Takes the `ExecutorOptions` fields."""
        _ray()  # fail now, in one line, when ray is not installed
        super().__init__(**options)
        self.owned = False
        self._slots: int | None = None

    @property
    def slots(self) -> int:
        """Tasks at once: ``--jobs``, else the cluster's CPUs over ``--cpus-per-task``. Asking
        connects to Ray: a batch with nothing left to run (``--resume``) never starts it."""
        if self._slots is None:
            self._connect()
        return self._slots

    def _connect(self) -> None:
        ray = _ray()
        if not ray.is_initialized():
            common = {"include_dashboard": False, "log_to_driver": False, "logging_level": "WARNING"}
            address = self.address or os.environ.get("RAY_ADDRESS")
            if address:
                try:
                    ray.init(address=address, **common)
                except (ConnectionError, RuntimeError, ValueError) as exc:
                    raise UsageError(
                        f"cannot reach the Ray cluster at {address}: {exc}",
                        hint="start it with `ray start --head` and give its address (HOST:6379)",
                    ) from None
            else:
                # "local": a Ray of our own even when another process's Ray runs on this machine
                # (plain ray.init() would join that one, and refuses num_cpus when it does)
                ray.init(
                    address="local",
                    num_cpus=math.ceil((self.jobs or os.cpu_count() or 1) * self.cpus),
                    object_store_memory=OBJECT_STORE_MB * 1024 * 1024,
                    **common,
                )
            self.owned = True
        res = ray.cluster_resources()
        if self.gpus > res.get("GPU", 0):
            self.close()
            raise UsageError(
                f"the Ray cluster has {res.get('GPU', 0):g} GPUs; a task asks for {self.gpus:g}",
                hint="start Ray on GPU nodes, or run on the CPU (--device cpu, --gpus-per-task 0)",
            )
        self._slots = self.jobs or max(1, int(res.get("CPU", 1) // self.cpus))

    def map(self, fn: Task, items: list[Any], on_stage: StageCallback | None = None) -> Iterator[TaskOutcome]:
        ray = _ray()
        from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

        slots = self.slots  # connects
        items = list(items)
        board = None
        if on_stage is not None:  # on the driver's node: a killed worker node must not take it along
            here = NodeAffinitySchedulingStrategy(ray.get_runtime_context().get_node_id(), soft=True)
            board = ray.remote(_Board).options(num_cpus=0, scheduling_strategy=here).remote()
        remote = ray.remote(_ray_task).options(num_cpus=self.cpus, num_gpus=self.gpus, max_retries=0)
        todo = list(range(len(items)))[::-1]
        attempts = [0] * len(items)
        running: dict[Any, int] = {}
        try:
            while todo or running:
                while todo and len(running) < slots:
                    i = todo.pop()
                    attempts[i] += 1
                    ref = remote.remote(fn, items[i], i, board, self.env, self.threads)
                    running[ref] = i
                ready, _ = ray.wait(list(running), num_returns=1, timeout=0.5)
                self._poll(board, on_stage)
                for ref in ready:
                    i = running.pop(ref)
                    try:
                        result = ray.get(ref)
                    except ray.exceptions.RayTaskError as exc:  # the task's own code raised
                        cause = getattr(exc, "cause", None) or exc
                        out = self._retry(i, f"{type(cause).__name__}: {cause}", attempts, todo)
                    except ray.exceptions.RayError as exc:  # worker, node or object lost
                        out = self._retry(i, f"{type(exc).__name__} (worker or node lost)", attempts, todo)
                    else:
                        out = finished(i, result, attempts[i])
                    if out is not None:
                        yield out
            self._poll(board, on_stage)
        finally:
            for ref in running:  # Ctrl-C or a driver error: stop what still runs
                try:
                    ray.cancel(ref, force=True)
                except Exception:
                    pass
            if board is not None:
                ray.kill(board)

    def _retry(self, i: int, reason: str, attempts: list[int], todo: list[int]) -> TaskOutcome | None:
        return retry_or_fail(i, reason, attempts, todo, self.retries)

    @staticmethod
    def _poll(board: Any, on_stage: StageCallback | None) -> None:
        if board is None or on_stage is None:
            return
        ray = _ray()
        try:
            stages = ray.get(board.drain.remote(), timeout=5)
        except Exception:  # progress is a nicety
            return
        for i, stage in stages.items():
            on_stage(i, stage)

    def close(self) -> None:
        if self.owned:
            _ray().shutdown()
            self.owned = False
        self._slots = None
