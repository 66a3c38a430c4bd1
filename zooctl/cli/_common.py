"""Shared CLI helpers: the store from the global option, rich consoles, JSON output."""

from __future__ import annotations

import contextlib
import json
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer
from rich.console import Console

if TYPE_CHECKING:
    from ..store.bank import Bank


def _own_suggestions() -> dict[str, Any]:
    """click >= 8.2 says "Did you mean 'list'?" itself; typer's own suggestion would say it twice."""
    import inspect

    import click

    supports = "suggest_commands" in inspect.signature(typer.Typer).parameters
    return {"suggest_commands": False} if supports and hasattr(click.exceptions, "NoSuchCommand") else {}


APP_OPTS = _own_suggestions()


class LineConsole(Console):
    """A rich console that, off a terminal (a log, a pipe, a test's runner), leaves each message one
    line: rich would break it at 80 columns there, paths and one-line errors included. Tables pass
    ``soft_wrap=False`` to keep their layout."""

    def print(self, *objects: Any, soft_wrap: bool | None = None, **kwargs: Any) -> None:
        super().print(*objects, soft_wrap=not self.is_terminal if soft_wrap is None else soft_wrap, **kwargs)


console = LineConsole()
err_console = LineConsole(stderr=True)


class State:
    store: Path | None = None


state = State()


def store_root() -> Path:
    from ..paths import default_store

    return state.store if state.store is not None else default_store()


def open_bank() -> Bank:
    """The bank of the store `store_root` names."""
    from ..store.bank import Bank

    return Bank.open(store_root())


def print_json(obj: Any) -> None:
    sys.stdout.write(json.dumps(obj, indent=2, sort_keys=False, default=_default) + "\n")


def _default(o: Any) -> Any:
    import numpy as np

    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


JsonOpt = typer.Option(False, "--json", help="Print JSON instead of a table (for scripts).")
# bank add and bank seed: unset follows ZOOCTL_VIEWS (`pipelines.bank_import.views_by_default`).
ViewsOpt = typer.Option(
    None,
    "--views/--no-views",
    help="Render and embed the added assets' retrieval views (default: on; ZOOCTL_VIEWS=0 turns the "
    "default off). `bank reindex --missing` adds them later.",
    show_default=False,
)
# Components by registered name (`zooctl plugins`): checked when the fit config is validated.
RendererOpt = typer.Option(None, "--renderer", help="Silhouette renderer: soft (default), fast, a plugin's.")
ArticulationOpt = typer.Option(
    None, "--articulation", help="Articulation model: casa (default), dqs, lbs, a plugin's."
)
# --device, declared here once for every command that runs torch.
DEVICE_HELP = "cpu or cuda"
DeviceOpt = typer.Option("cpu", "--device", help=f"{DEVICE_HELP}.")
# fit and bench fit: unset keeps the device of the fit config (a --config file's, else cpu).
ConfigDeviceOpt = typer.Option(
    None, "--device", help=f"{DEVICE_HELP} (default: a --config file's, else cpu)."
)
# The fit config's sources, shared by fit and bench run.
PresetOpt = typer.Option(
    "fast",
    "--preset",
    help="fast or quality (fast fitted 2.4 times as long: a closer input view, not a truer 3D; about 1.7 "
    "times the time with retrieval; BENCHMARKS.md).",
)
FitConfigOpt = typer.Option(
    None,
    "--config",
    help='JSON fit config applied on top of the preset, e.g. {"weights": {"pose_prior": 0.1}} (the '
    "command's own options win where both set a field).",
)
# Sampling a motion prior, shared by animate and bench motion.
PriorOpt = typer.Option(None, "--prior", help="Motion prior (default: the most recently trained).")
TemperatureOpt = typer.Option(
    None,
    "--temperature",
    min=0.0,
    help="Scale of the prior's latent standard deviation: lower is closer to typical motion, higher more "
    "varied. Default: the prior's (see `zooctl motion list`).",
    show_default=False,
)


def print_table(columns: list[tuple[str, str]], rows: list[list[str]], title: str | None = None) -> None:
    """Print an aligned table: a bold header and plain rows.

    ``columns`` are (header, "left"|"right"). Not Rich's Table, which is too slow for `bank list`
    on a large bank (BENCHMARKS.md, "Measurements behind code choices"); this reads the same.
    """
    widths = [len(h) for h, _ in columns]
    for r in rows:
        for i, cell in enumerate(r):
            widths[i] = max(widths[i], len(cell))

    def fmt(cells: list[str]) -> str:
        out = [
            c.ljust(w) if just == "left" else c.rjust(w) for c, w, (_, just) in zip(cells, widths, columns)
        ]
        return "  ".join(out).rstrip()

    if title:
        console.print(title, style="bold", highlight=False, markup=False)
    header = fmt([h for h, _ in columns])
    console.print(header, style="bold", highlight=False, markup=False)
    console.print("  ".join("-" * w for w in widths), style="dim", highlight=False, markup=False)
    console.file.write("\n".join(fmt(r) for r in rows) + ("\n" if rows else ""))
    console.file.flush()


def print_listing(
    rows: list[dict[str, Any]],
    json_out: bool,
    columns: list[tuple[str, str]],
    cells: Callable[[dict[str, Any]], list[str]],
    title: str | None = None,
    empty: str | None = None,
) -> None:
    """A `list` command's output: ``rows`` as JSON, or as a `print_table` of ``columns`` with
    ``cells(row)`` a row; ``empty``: a line in place of an empty table."""
    if json_out:
        print_json(rows)
    elif not rows and empty is not None:
        console.print(empty, highlight=False, markup=False)
    else:
        print_table(columns, [cells(r) for r in rows], title=title)


@contextlib.contextmanager
def stage_progress(enabled: bool, transient: bool = False) -> Iterator[object]:
    """A rich progress display with one bar per stage; yields the ``(stage, done, total)`` callback.
    ``transient``: the bars are cleared when it ends."""
    if not enabled:
        yield None
        return
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    with Progress(
        TextColumn("{task.description:>8}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=err_console,
        transient=transient,
    ) as prog:
        tasks: dict[str, object] = {}

        def update(stage: str, done: int, total: int | None) -> None:
            if stage not in tasks:
                tasks[stage] = prog.add_task(stage, total=total)
            prog.update(tasks[stage], completed=done, total=total)

        yield update


def print_skipped(skipped: dict[str, str], what: str) -> None:
    """One warning line per file a store command could not use."""
    from rich.markup import escape

    for name, why in skipped.items():
        err_console.print(
            f"[yellow]skipped[/] {escape(name)} ({what}): {escape(why)}", highlight=False, soft_wrap=True
        )


def print_repair(report: dict[str, Any], items: str) -> None:
    """What `bank repair` / `video repair` did (`zooctl.store.indexed.IndexedStore.repair`, and
    for the bank `zooctl.pipelines.bank_import.repair_bank`)."""
    from rich.markup import escape

    n = len(report["indexed"])
    verb = "rebuilt" if report["written"] else "checked (nothing to change)"
    console.print(
        f"index {verb}: {n} {items} indexed; the previous index was {report['previous']}",
        highlight=False,
        markup=False,
    )
    for note in report["fixed"]:
        console.print(f"  {note}", highlight=False, markup=False)
    print_skipped(report["skipped"], "not a valid file, left in place")
    if report["dropped"]:
        err_console.print(
            f"[yellow]dropped from the index[/] (no valid file): {escape(', '.join(report['dropped']))}",
            highlight=False,
            soft_wrap=True,
        )
    if report.get("views_rendered"):
        console.print(
            f"rendered the retrieval views a stopped `bank add` left out: {', '.join(report['views_rendered'])}",
            highlight=False,
            markup=False,
            soft_wrap=True,
        )
    for name, why in (report.get("views_failed") or {}).items():
        err_console.print(
            f"[yellow]views not rendered[/] {escape(name)}: {escape(why)} "
            f"(`zooctl bank reindex {escape(name)}` tries again)",
            highlight=False,
            soft_wrap=True,
        )


def add_rm_command(app: typer.Typer, open_store: Callable[[], Any], help: str, names_help: str) -> None:
    """Add `rm NAMES...` of a name-keyed store (``open_store()``) to ``app``."""

    def rm(names: list[str] = typer.Argument(..., help=names_help)) -> None:
        store = open_store()
        for n in names:
            store.remove(n)
            console.print(f"removed {n}", highlight=False, markup=False)

    app.command("rm", help=help)(rm)


def add_upkeep_commands(
    app: typer.Typer,
    open_store: Callable[[], Any],
    items: str,
    clean_help: str,
    repair_help: str,
    repair_store: Callable[[Any], dict[str, Any]] | None = None,
) -> None:
    """Add `clean` and `repair` of an indexed store (`zooctl.store.indexed.IndexedStore`, from
    ``open_store()``) to ``app``; ``items`` names what it holds in the output ("assets").
    ``repair_store(store)``: what `repair` runs (default: ``store.repair()``)."""

    def clean(json_out: bool = JsonOpt) -> None:
        store = open_store()
        report = store.cleanup()
        if json_out:
            print_json(report)
        else:
            print_clean(report, store.noun, store.repair_cmd)

    def repair(json_out: bool = JsonOpt) -> None:
        store = open_store()
        report = store.repair() if repair_store is None else repair_store(store)
        if json_out:
            print_json(report)
        else:
            print_repair(report, items)

    app.command("clean", help=clean_help)(clean)
    app.command("repair", help=repair_help)(repair)


def print_clean(report: dict[str, Any], noun: str, repair_cmd: str) -> None:
    """What `bank clean` / `video clean` removed, and the unindexed files it kept."""
    console.print(
        f"removed {report['temporaries']} temporaries and {report['orphans']} leftover files",
        highlight=False,
    )
    if report["unindexed"]:
        err_console.print(
            f"kept {len(report['unindexed'])} {noun} files the index does not name "
            f"({', '.join(report['unindexed'])}): run `{repair_cmd}` to index the valid ones",
            highlight=False,
            markup=False,
            soft_wrap=True,
        )
    print_views_pending(report.get("views_pending") or [])


def print_views_pending(names: list[str]) -> None:
    """One line on the assets whose retrieval views a stopped `bank add` never rendered."""
    if names:
        shown = ", ".join(names[:5]) + (f" and {len(names) - 5} more" if len(names) > 5 else "")
        err_console.print(
            f"{len(names)} asset{'s' if len(names) > 1 else ''} without the retrieval views their "
            f"`bank add` was rendering when it stopped ({shown}): `bank search` leaves "
            f"{'them' if len(names) > 1 else 'it'} out; run `zooctl bank repair` to render them",
            style="yellow",
            highlight=False,
            markup=False,
            soft_wrap=True,
        )
