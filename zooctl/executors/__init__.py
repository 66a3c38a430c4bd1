"""Executors: where the tasks of a batch run (this process, a process pool, a Ray cluster).

An executor is a component of kind ``executor`` (hook `zooctl.hookspecs.register_executors`):
the built-in ``local`` one is in `zooctl.executors.local`, ``ray`` comes with the first-party
plugin distribution ``plugins/zooctl-ray``. `zooctl.pipelines.batch` drives them: executors only
run tasks and report what happened; they never touch the store.
"""

from __future__ import annotations

from .base import Executor, ExecutorOptions, TaskOutcome, call_task, get_executor

__all__ = ["Executor", "ExecutorOptions", "TaskOutcome", "call_task", "get_executor"]
