"""`zooctl` entry point: the root app, global options, command-group registration, error formatting."""

from __future__ import annotations

import os
import sys
import traceback
from pathlib import Path
from typing import Any

import click
import typer
from rich.markup import escape
from typer.core import TyperGroup

from .. import __version__
from ..errors import Terminated, ZooctlError
from ._common import APP_OPTS, err_console, state

# Before torch is imported anywhere: a spinning OpenMP pool slows every render on a busy machine
# (BENCHMARKS.md, "Differentiable renderers"); passive waiting costs nothing when idle.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


class _Group(TyperGroup):
    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except EOFError as exc:  # Click would print only "Aborted!" for it
            raise RuntimeError(f"a file or stream ended early: {exc}") from exc
        except KeyboardInterrupt as exc:  # Typer would exit 130 without a word, SIGTERM too
            raise _Stopped(isinstance(exc, Terminated)) from exc


class _Stopped(BaseException):
    """Ctrl-C or SIGTERM (``terminated``) on its way out past Click, for `run` to report."""

    def __init__(self, terminated: bool):
        super().__init__()
        self.terminated = terminated


app = typer.Typer(
    **APP_OPTS,
    cls=_Group,
    name="zooctl",
    help="Rigged 3D characters from casual animal videos, and new motions for them.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode="rich",
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"zooctl {__version__}")
        raise typer.Exit()


@app.callback()
def main(
    store: Path = typer.Option(
        None,
        "--store",
        envvar="ZOOCTL_STORE",
        help="Data root (asset bank, videos, fits). Default: ./store in a checkout, else the user data dir.",
        show_default=False,
    ),
    wait: float = typer.Option(
        None,
        "--wait",
        help="Seconds a writer waits for another zooctl process's store lock before giving up "
        "(default: ZOOCTL_LOCK_TIMEOUT, else 120).",
        show_default=False,
    ),
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="Print the version and exit."
    ),
) -> None:
    from ..paths import use_store
    from ..store import fs

    state.store = store
    use_store(store)  # model weights kept in the store (STORE/models) follow --store too
    if wait is not None:
        fs.set_lock_timeout(wait)
    fs.on_lock_wait = _tell_lock_wait


def _tell_lock_wait(holder: str) -> None:
    from ..store import fs

    err_console.print(
        f"waiting for the store lock, held by {escape(holder)} (up to {fs.LOCK_TIMEOUT_S:g} s; --wait to change)",
        highlight=False,
        soft_wrap=True,
    )


def _register_groups() -> None:
    """Every command group is registered here, in one place (once: `run` is called many times
    in one process by tests, and each copy of a group slowed every later call)."""
    if app.registered_groups:
        return
    from . import animate, bank, bench, embed, motion, plugins_cmd, segment, video

    app.add_typer(bank.app, name="bank")
    app.add_typer(bench.app, name="bench")
    app.add_typer(video.app, name="video")
    app.add_typer(motion.app, name="motion")
    app.add_typer(embed.app, name="embed")
    app.add_typer(segment.app, name="segment")
    app.command("animate")(animate.animate)
    app.command("plugins")(plugins_cmd.plugins)
    from . import fit, fits

    app.command("fit")(fit.fit)
    app.add_typer(fits.app, name="fits")


def _builtin_names() -> set[str]:
    names = {g.name for g in app.registered_groups}
    names |= {c.name or c.callback.__name__ for c in app.registered_commands}
    return names


def _first_command(argv: list[str]) -> str | None:
    it = iter(argv)
    for a in it:
        if a in ("--store", "--wait"):
            next(it, None)
        elif not a.startswith("-"):
            return a
    return None


def _register_plugin_commands(argv: list[str]) -> None:
    """Load plugins for their extra commands, unless the command is a built-in one: plugin
    loading costs an entry-point scan and module imports that `bank show` should not pay."""
    if _first_command(argv) in _builtin_names() and "--help" not in argv:
        return
    from ..plugins import get_plugin_manager

    try:
        pm = get_plugin_manager()
    except ZooctlError as exc:
        err_console.print(f"[yellow]warning:[/] {escape(exc.message)}", highlight=False)
        return
    pm.add_commands(app)
    for info in pm.failures():
        err_console.print(
            f"[yellow]warning:[/] plugin {info.name!r} ({info.distribution}) skipped: {escape(info.error)}",
            highlight=False,
        )


def run(argv: list[str] | None = None) -> int:
    """Console-script entry point. Returns the exit code (also used by tests in-process)."""
    debug = os.environ.get("ZOOCTL_DEBUG", "") not in ("", "0")
    try:
        args = list(sys.argv[1:] if argv is None else argv)
        _register_groups()
        _register_plugin_commands(args)
        # Typer's standalone mode prints usage errors (exit 2) and help; our errors come out here.
        app(args=args, prog_name="zooctl")
        return 0
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except ZooctlError as exc:
        if debug:
            traceback.print_exc()
        err_console.print(f"[bold red]error:[/] {escape(exc.message)}", highlight=False, soft_wrap=True)
        if exc.hint:
            err_console.print(f"  [dim]hint:[/] {escape(exc.hint)}", highlight=False, soft_wrap=True)
        return exc.exit_code
    except (_Stopped, KeyboardInterrupt) as exc:
        stop = exc.terminated if isinstance(exc, _Stopped) else isinstance(exc, Terminated)
        err_console.print("terminated" if stop else "interrupted")
        return 143 if stop else 130
    except Exception as exc:
        if debug:
            traceback.print_exc()
        err_console.print(
            f"[bold red]error:[/] internal failure: {type(exc).__name__}: {escape(str(exc))}",
            highlight=False,
            soft_wrap=True,
        )
        err_console.print(
            "  [dim]hint:[/] run again with ZOOCTL_DEBUG=1 for the traceback, and report it", highlight=False
        )
        return 1


def _on_sigterm(_signum: int, _frame: Any) -> None:
    import signal

    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # a second SIGTERM ends the process at once
    raise Terminated()


def entry() -> None:
    import signal

    signal.signal(signal.SIGTERM, _on_sigterm)
    _exit(run())


def _exit(code: int) -> None:
    """Leave the process with ``code`` without tearing the interpreter down: the exit handlers
    run (atexit: multiprocessing, Ray, logging, h5py, temporary directories) and the streams are
    flushed, then ``os._exit``. Tearing down the modules torch loads costs about half a second of
    every command that imports it. Falls back to a normal exit while another Python thread is
    alive (a normal exit waits for it) or with ZOOCTL_SLOW_EXIT=1."""
    import threading

    if threading.active_count() > 1 or os.environ.get("ZOOCTL_SLOW_EXIT", "") not in ("", "0"):
        sys.exit(code)
    import atexit

    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe (`zooctl ... | head`) or a closed stream
            pass
    os._exit(code)


if __name__ == "__main__":  # pragma: no cover
    entry()
