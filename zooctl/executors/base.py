"""The executor contract shared by every executor, and the wrapper each task runs in.

A task is ``fn(item, report)``: ``fn`` a module-level function (pickled by reference, so a worker
imports it), ``item`` its picklable input, ``report(stage)`` a callable that names the stage the
task is in (shown on the driver's progress bar). The task returns a picklable value.

Failure semantics every executor follows:

- a `zooctl.errors.ZooctlError` from the task is the item's fault (bad input): it is reported
  at once, never retried;
- any other exception, or a worker or node that dies under the task, is retried, at most
  ``retries`` more times; after that the item fails with the last reason.
"""

from __future__ import annotations

import math
import os
import socket
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, Protocol

from ..errors import UsageError, ZooctlError

Task = Callable[[Any, Callable[[str], None]], Any]
StageCallback = Callable[[int, str], None]


@dataclass
class TaskOutcome:
    """What became of one item: its value, or why it failed, and how many attempts it took."""

    index: int
    value: Any = None
    error: str | None = None
    hint: str | None = None
    attempts: int = 1
    where: str = ""  # host:pid of the worker that ran the last attempt

    @property
    def ok(self) -> bool:
        return self.error is None


@dataclass
class ExecutorOptions:
    """The options every executor factory accepts (``--jobs``, ``--address`` ...)."""

    jobs: int | None = None  # tasks at once (None: the executor's default)
    address: str | None = None  # a cluster to join (ray); local rejects it
    cpus_per_task: float = 1.0  # also the torch threads of each task
    gpus_per_task: float = 0.0
    retries: int = 2  # extra attempts of a crashed task (bad input is never retried)
    env: dict[str, str] = field(default_factory=dict)  # set in the worker before each task

    def validate(self) -> ExecutorOptions:
        if self.jobs is not None and self.jobs < 1:
            raise UsageError("--jobs must be at least 1")
        if self.cpus_per_task <= 0 or self.gpus_per_task < 0:
            raise UsageError("--cpus-per-task must be positive and --gpus-per-task not negative")
        if self.retries < 0:
            raise UsageError("retries must not be negative")
        return self


class Executor(Protocol):
    name: str
    slots: int  # how many tasks run at once

    def map(self, fn: Task, items: list[Any], on_stage: StageCallback | None = None) -> Iterator[TaskOutcome]:
        """Run ``fn`` on every item; yield one outcome per item as each finishes (any order).
        Closing the iterator early (or an exception in the driver) cancels what still runs."""
        ...

    def close(self) -> None: ...


class ExecutorBase:
    """What every executor keeps of its `ExecutorOptions`: the size of the pool it asks for, the
    torch threads and environment of each task, and how often a crashed task is retried."""

    def __init__(
        self,
        jobs: int | None = None,
        address: str | None = None,
        cpus_per_task: float = 1.0,
        gpus_per_task: float = 0.0,
        retries: int = 2,
        env: dict[str, str] | None = None,
    ) -> None:
        self.jobs, self.address = jobs, address
        self.cpus, self.gpus, self.retries = cpus_per_task, gpus_per_task, retries
        self.threads = max(1, math.floor(cpus_per_task))
        self.env = {**task_env(), **(env or {})}


def where() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def call_task(
    fn: Task, item: Any, report: Callable[[str], None], env: dict[str, str], threads: int
) -> tuple[str, Any, Any, str]:
    """Run one task in a worker: ``("ok", value, None, where)`` or, for bad input,
    ``("error", message, hint, where)``. Other exceptions propagate so the executor retries."""
    os.environ.update(env)  # what the driver saw (ZOOCTL_*, device), whichever machine this is
    os.environ["OMP_NUM_THREADS"] = str(threads)
    import sys

    if "torch" in sys.modules:  # a reused worker: the env var only counts at import
        sys.modules["torch"].set_num_threads(threads)
    try:
        return "ok", fn(item, report), None, where()
    except ZooctlError as exc:
        return "error", exc.message, exc.hint, where()


def finished(i: int, result: tuple[str, Any, Any, str], attempts: int) -> TaskOutcome:
    """The outcome of item ``i`` whose task returned ``result`` (what `call_task` returns)."""
    status, a, b, w = result
    if status == "ok":
        return TaskOutcome(i, value=a, attempts=attempts, where=w)
    return TaskOutcome(i, error=a, hint=b, attempts=attempts, where=w)


def crashed(i: int, attempts: int, reason: str) -> TaskOutcome:
    """The outcome of item ``i`` whose every attempt crashed (``reason``: the last one's)."""
    return TaskOutcome(
        i,
        error=f"crashed {attempts} times; last: {reason}",
        hint="run it alone with ZOOCTL_DEBUG=1 to see the traceback",
        attempts=attempts,
    )


def retry_or_fail(
    i: int, reason: str, attempts: list[int], todo: list[int], retries: int
) -> TaskOutcome | None:
    """After a crash of item ``i``: queue it on ``todo`` again while ``attempts[i] <= retries``
    (returns None), else its failure."""
    if attempts[i] <= retries:
        todo.append(i)
        return None
    return crashed(i, attempts[i], reason)


def task_env() -> dict[str, str]:
    """The driver's settings a worker must share: zooctl's own variables and thread limits."""
    keep = ("ZOOCTL_", "OMP_WAIT_POLICY")
    return {k: v for k, v in os.environ.items() if k.startswith(keep) and k != "ZOOCTL_DEBUG"}


def get_executor(name: str, **options: Any) -> Executor:
    """Build the executor registered as ``name`` with `ExecutorOptions` fields as keywords."""
    from ..errors import NotFoundError
    from ..plugins import get_registry

    opts = ExecutorOptions(**options).validate()
    try:
        spec = get_registry().get("executor", name)
    except NotFoundError as exc:
        if name == "ray":
            raise NotFoundError(
                "no executor named 'ray': the zooctl-ray plugin is not installed",
                hint="pip install plugins/zooctl-ray (it installs ray too)",
            ) from None
        raise exc
    return spec.create(**opts.__dict__)
