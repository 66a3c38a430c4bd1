"""Run a batch of items on an executor; the driver (this process) is the store's one writer.

Workers compute and return results; `run_batch` hands each result to ``commit`` in this process
as it arrives, which writes it to the store under the store's lock with atomic replaces. So a
result lands once: an attempt that died returned nothing, and an item's one returned result is
committed once. ``--resume`` (``skip``) leaves out the items the store already holds, so a batch
that was interrupted and run again finishes the rest and repeats nothing.

Per-item failures (bad input, a crash that outlived its retries, a commit that failed) are
listed in the report and the other items go on. Ctrl-C cancels the running tasks, keeps what was
committed and raises `BatchInterrupted` with the report so far.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from ..errors import ZooctlError
from ..executors.base import Executor, Task


@dataclass
class BatchItem:
    key: str  # what the user knows the item by (fit name, asset name)
    payload: Any  # the task's input (picklable)
    label: str = ""  # the input as given (path, glob match, stored name)
    error: ZooctlError | None = None  # known bad before any task runs: fails without one


@dataclass
class ItemResult:
    key: str
    label: str
    status: str  # done | failed | skipped
    summary: dict[str, Any] = field(default_factory=dict)
    error: str | None = None
    hint: str | None = None
    attempts: int = 0
    where: str = ""
    commit_s: float = 0.0  # the driver's time storing it (the one writer's cost per item)

    def to_json(self) -> dict[str, Any]:
        return {
            "key": self.key,
            "input": self.label,
            "status": self.status,
            "error": self.error,
            "hint": self.hint,
            "attempts": self.attempts,
            "where": self.where,
            "commit_s": round(self.commit_s, 4),
            **self.summary,
        }


@dataclass
class BatchReport:
    executor: str
    slots: int
    results: list[ItemResult]
    wall_s: float = 0.0
    interrupted: bool = False

    def count(self, status: str) -> int:
        return sum(r.status == status for r in self.results)

    @property
    def failed(self) -> list[ItemResult]:
        return [r for r in self.results if r.status == "failed"]

    def to_json(self) -> dict[str, Any]:
        return {
            "executor": self.executor,
            "slots": self.slots,
            "wall_s": round(self.wall_s, 3),
            "interrupted": self.interrupted,
            "done": self.count("done"),
            "skipped": self.count("skipped"),
            "failed": self.count("failed"),
            "items": [r.to_json() for r in self.results],
        }


class BatchInterrupted(KeyboardInterrupt):
    """Ctrl-C (or SIGTERM) during a batch: what was committed stays; ``report`` says what that
    is, ``stop`` is what stopped it."""

    def __init__(self, report: BatchReport, stop: KeyboardInterrupt | None = None):
        super().__init__("batch interrupted")
        self.report = report
        self.stop = stop


class Progress:
    """What `run_batch` tells its caller; every method is optional to override."""

    def start(self, total: int, skipped: int) -> None: ...

    def stage(self, key: str, stage: str) -> None: ...

    def finished(self, result: ItemResult) -> None: ...


def run_batch(
    executor: Executor,
    fn: Task,
    items: list[BatchItem],
    commit: Callable[[BatchItem, Any], dict[str, Any]],
    skip: Callable[[BatchItem], dict[str, Any] | None] | None = None,
    progress: Progress | None = None,
) -> BatchReport:
    """Run ``fn`` on every item not skipped and commit each result as it arrives.

    ``skip(item)`` returns the summary of an item the store already holds (``--resume``), else
    None. ``commit(item, value)`` stores a result and returns its summary for the report; a
    `ZooctlError` from it fails that item only.
    """
    progress = progress or Progress()
    t0 = time.perf_counter()
    results: list[ItemResult | None] = [None] * len(items)
    todo: list[int] = []
    for i, it in enumerate(items):
        done = skip(it) if skip is not None and it.error is None else None
        if it.error is not None:
            results[i] = ItemResult(it.key, it.label, "failed", error=it.error.message, hint=it.error.hint)
        elif done is not None:
            results[i] = ItemResult(it.key, it.label, "skipped", summary=done)
        else:
            todo.append(i)
    # Only a batch with work asks for slots: a cluster executor may connect (start Ray) to say.
    report = BatchReport(executor.name, executor.slots if todo else 0, [])
    progress.start(len(items), sum(1 for r in results if r is not None and r.status == "skipped"))
    for r in results:
        if r is not None:
            progress.finished(r)
    if not todo:
        report.results = [r for r in results if r is not None]
        report.wall_s = time.perf_counter() - t0
        return report

    def on_stage(j: int, stage: str) -> None:
        progress.stage(items[todo[j]].key, stage)

    outcomes = executor.map(fn, [items[i].payload for i in todo], on_stage)
    try:
        for out in outcomes:
            i = todo[out.index]
            if results[i] is not None:  # an executor must not deliver twice; never commit twice
                continue
            it = items[i]
            res = ItemResult(it.key, it.label, "done", attempts=out.attempts, where=out.where)
            if out.ok:
                t = time.perf_counter()
                try:
                    res.summary = commit(it, out.value)
                except ZooctlError as exc:
                    res.status, res.error, res.hint = "failed", exc.message, exc.hint
                res.commit_s = time.perf_counter() - t
            else:
                res.status, res.error, res.hint = "failed", out.error, out.hint
            results[i] = res
            progress.finished(res)
    except KeyboardInterrupt as exc:
        _close(outcomes)
        report.results = [r for r in results if r is not None]
        report.wall_s, report.interrupted = time.perf_counter() - t0, True
        raise BatchInterrupted(report, exc) from None
    finally:
        _close(outcomes)
    report.results = [r for r in results if r is not None]
    report.wall_s = time.perf_counter() - t0
    return report


def _close(outcomes: Any) -> None:
    close = getattr(outcomes, "close", None)
    if close is not None:
        try:
            close()  # runs the executor's cleanup: running tasks are cancelled
        except Exception:
            pass
