"""What every batch command shares: the executor options, a progress bar over tasks, the summary.

The batch logic is `zooctl.pipelines.batch`; this module only turns options into an executor and
a report into lines and an exit code.
"""

from __future__ import annotations

import functools
import inspect
import math
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import typer

from ..errors import Terminated
from ..pipelines.batch import BatchInterrupted, BatchReport, ItemResult, Progress
from ._common import console, err_console, print_json, print_table

ExecutorOpt = typer.Option(
    None,
    "--executor",
    help="Run as a batch on an executor: local (this machine) or ray (plugin zooctl-ray); see `zooctl plugins`.",
)
JobsOpt = typer.Option(
    None,
    "--jobs",
    help="Tasks at once (local: worker processes; default for fits on the CPU as many as the cores and "
    "memory hold, at most one a video, else 1; ray: default the cluster's CPUs / --cpus-per-task).",
)
AddressOpt = typer.Option(
    None, "--address", help="Ray cluster to join (HOST:PORT; or RAY_ADDRESS). Default: start Ray here."
)
CpusOpt = typer.Option(
    None,
    "--cpus-per-task",
    help="CPUs each task asks for (and its torch threads; default 1, or for fits run here on the CPU "
    "the cores shared out between the fits at once).",
)
GpusOpt = typer.Option(
    None,
    "--gpus-per-task",
    help="GPUs each task asks for (default with --device cuda: 1, or for fits run here a share of one, "
    "up to four fits a GPU and one a host core; 0.25 runs four tasks on one GPU). Locally, without "
    "--jobs, as many tasks at once as the machine's GPUs hold.",
)


@dataclass(frozen=True)
class BatchOptions:
    """What a batch command's executor options say (`with_batch_options` fills it in)."""

    executor: str | None = None
    jobs: int | None = None
    address: str | None = None
    cpus: float | None = None
    gpus: float | None = None

    def make_executor(self, device: str | None, fits: int | None = None):
        """The executor these options name (default local), for ``fits`` fits (None: other tasks).
        --gpus-per-task defaults to 1 on CUDA and --cpus-per-task to 1. Run here, fits fill the
        machine unless the options say otherwise: on CUDA they share each GPU (`tasks_per_gpu`),
        on the CPU as many run at once as the cores and memory hold (`fits_at_once`), and the
        cores are shared out between them."""
        from ..executors import get_executor

        gpus, jobs, cpus = self.gpus, self.jobs, self.cpus
        cuda = (device or "cpu").startswith("cuda")
        local = (self.executor or "local") == "local"
        here = local and fits is not None
        if gpus is None:
            gpus = 1.0 if cuda else 0.0
            if local and ":" in (device or ""):
                gpus = 0.0  # `cuda:N` names the GPU: every task on it, none placed elsewhere
            elif here and cuda:
                from ..executors.local import visible_gpus
                from ..pipelines.batch_fit import FITS_PER_GPU

                share = tasks_per_gpu(FITS_PER_GPU, cpus or 1.0, len(visible_gpus()), usable_cores())
                gpus = 1.0 / share
        if here and not cuda:
            cores = usable_cores()
            if jobs is None:
                jobs = fits_at_once(fits, cpus or 1.0, cores, available_memory_gb())
            if cpus is None:
                cpus = float(max(1, cores // jobs))
        return get_executor(
            self.executor or "local",
            jobs=jobs,
            address=self.address,
            cpus_per_task=cpus or 1.0,
            gpus_per_task=gpus,
        )


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity where the system says, else all)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def available_memory_gb() -> float | None:
    """Memory available to new processes (Linux's MemAvailable), or None where unknown."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) / 2**20
    except (OSError, ValueError, IndexError):
        pass
    return None


def fits_at_once(fits: int, cpus_per_task: float, cores: int, memory_gb: float | None) -> int:
    """How many of ``fits`` fits run at once on the CPU by default: one a ``cpus_per_task``
    cores, no more than ``memory_gb`` holds at `FIT_MEMORY_GB` each (unknown: no bound), at least 1."""
    from ..pipelines.batch_fit import FIT_MEMORY_GB

    n = min(fits, math.floor(cores / cpus_per_task + 1e-9))
    if memory_gb is not None:
        n = min(n, math.floor(memory_gb / FIT_MEMORY_GB))
    return max(1, n)


def tasks_per_gpu(most: int, cpus_per_task: float, gpus: int, cores: int) -> int:
    """How many tasks of ``cpus_per_task`` host cores each share one of ``gpus`` GPUs by default:
    ``most``, or fewer where the host has fewer cores a GPU for them (at least 1)."""
    fit = math.floor(cores / max(gpus, 1) / cpus_per_task + 1e-9)
    return max(1, min(most, fit))


# The default of a command's ``batch: BatchOptions`` parameter: `with_batch_options` puts the
# options below in its place (same order in --help) and passes the command one `BatchOptions`.
BatchOpts: Any = object()

_OPTIONS = (  # (parameter, type, option, BatchOptions field)
    ("executor", str, ExecutorOpt, "executor"),
    ("jobs", int, JobsOpt, "jobs"),
    ("address", str, AddressOpt, "address"),
    ("cpus_per_task", float, CpusOpt, "cpus"),
    ("gpus_per_task", float, GpusOpt, "gpus"),
)


def with_batch_options(command: Callable[..., Any]) -> Callable[..., Any]:
    """Give a Typer command the executor options: its ``batch`` parameter (default `BatchOpts`)
    becomes --executor, --jobs, --address, --cpus-per-task and --gpus-per-task."""
    sig = inspect.signature(command, eval_str=True)
    params: list[inspect.Parameter] = []
    for p in sig.parameters.values():
        if p.default is BatchOpts:
            params += [inspect.Parameter(n, p.kind, default=opt, annotation=t) for n, t, opt, _ in _OPTIONS]
        else:
            params.append(p)

    @functools.wraps(command)
    def run(**kwargs: Any) -> Any:
        batch = BatchOptions(**{field: kwargs.pop(n) for n, _, _, field in _OPTIONS})
        return command(**kwargs, batch=batch)

    run.__signature__ = sig.replace(parameters=params)  # type: ignore[attr-defined]
    run.__annotations__ = {p.name: p.annotation for p in params}
    return run


class RichBatchProgress(Progress):
    """One bar over the batch's tasks, with the stage each running task is in."""

    def __init__(self, enabled: bool = True) -> None:
        from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeElapsedColumn
        from rich.progress import Progress as RichProgress

        self.enabled = enabled
        self.bar = RichProgress(
            TextColumn("[bold]tasks"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            TextColumn("{task.fields[running]}"),
            console=err_console,
            disable=not enabled,
        )
        self.task: Any = None
        self.running: dict[str, str] = {}

    def __enter__(self) -> RichBatchProgress:
        self.bar.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.bar.stop()

    def start(self, total: int, skipped: int) -> None:
        self.task = self.bar.add_task("", total=total, running="")
        if skipped:
            self.bar.console.print(f"{skipped} of {total} done already (--resume): skipped", highlight=False)

    def _show(self) -> None:
        text = ", ".join(f"{k}: {s}" for k, s in list(self.running.items())[:4])
        self.bar.update(self.task, running=text + (" ..." if len(self.running) > 4 else ""))

    def stage(self, key: str, stage: str) -> None:
        self.running[key] = stage
        self._show()

    def finished(self, result: ItemResult) -> None:
        self.running.pop(result.key, None)
        self.bar.update(self.task, advance=1)
        self._show()
        if result.status == "failed" and self.enabled:
            self.bar.console.print(
                f"[red]failed[/] {result.key}: {result.error}", highlight=False, markup=True
            )


def run_cli_batch(executor, fn, items, commit, skip, json_out: bool) -> BatchReport:
    """`run_batch` with the progress bar; Ctrl-C prints what finished and exits 130."""
    from ..pipelines.batch import run_batch

    try:
        with RichBatchProgress(enabled=not json_out) as prog:
            return run_batch(executor, fn, items, commit, skip=skip, progress=prog)
    except BatchInterrupted as exc:
        say_interrupted(exc.report, len(items))
        raise typer.Exit(stop_code(exc)) from None
    finally:
        executor.close()


def stop_code(exc: BatchInterrupted) -> int:
    """The exit code of a stopped batch: 143 for SIGTERM, 130 for Ctrl-C."""
    return 143 if isinstance(exc.stop, Terminated) else 130


def say_interrupted(report: BatchReport, total: int | None) -> None:
    left = f", {total - len(report.results)} not finished" if total is not None else ""
    err_console.print(
        f"interrupted: {report.count('done')} done, {report.count('skipped')} skipped{left}; "
        "run the same command with --resume to finish",
        highlight=False,
    )


def report_batch(
    report: BatchReport,
    json_out: bool,
    what: str,
    columns: list[tuple[str, str]],
    row: Callable[[ItemResult], list[str]],
) -> None:
    """Print the summary (a table, or ``--json``) and fail with one line if any item failed."""
    from ..errors import UsageError

    if json_out:
        print_json(report.to_json())
    else:
        print_table(
            [("item", "left"), ("status", "left"), *columns, ("tries", "right"), ("error", "left")],
            [
                [r.key, r.status, *row(r), str(r.attempts or "-"), (r.error or "")[:120]]
                for r in report.results
            ],
            title=f"{report.count('done')} {what} done, {report.count('skipped')} skipped, "
            f"{report.count('failed')} failed in {report.wall_s:.1f} s ({report.executor}, {report.slots} at once)",
        )
        for r in report.failed:
            if r.hint:
                console.print(f"  {r.key}: hint: {r.hint}", highlight=False, markup=False)
    if report.failed:
        raise UsageError(
            f"{len(report.failed)} of {len(report.results)} {what} failed",
            hint="the others are stored; fix the inputs named above and run again with --resume",
        )
