"""`zooctl view`: build the site (a fit or the bank gallery), then export it or serve it."""

from __future__ import annotations

import signal
import tempfile
import webbrowser
from contextlib import contextmanager
from functools import partial
from pathlib import Path

from zooctl.errors import UsageError


def run_view(
    fit: str | None,
    bank: bool,
    tags: list[str],
    export: Path | None,
    host: str,
    port: int,
    no_browser: bool,
    bench: Path | None = None,
    animate: Path | None = None,
) -> None:
    from zooctl.cli._common import console, store_root

    if (fit is not None) + bank + (bench is not None) + (animate is not None) != 1:
        raise UsageError(
            "give a FIT to view, or --bank for the bank gallery, --bench DIR for a benchmark's table, "
            "or --animate DIR for sampled motions",
            hint="`zooctl fits list` names the fits",
        )
    if tags and not bank:
        raise UsageError("--tag filters the bank gallery: use it with --bank")
    store = store_root()
    what = (
        f"fit {fit}"
        if fit
        else "the bank gallery"
        if bank
        else f"the benchmark table of {bench}"
        if bench
        else f"the motions in {animate}"
    )
    if export is not None:
        index = _build(store, fit, tags, Path(export), bench, animate)
        console.print(f"wrote {index} (open it in a browser; it works from disk)", highlight=False)
        return
    with tempfile.TemporaryDirectory(prefix="zooctl-view-") as d:
        _build(store, fit, tags, Path(d), bench, animate)
        _serve(Path(d), host, port, no_browser, what)


def _build(
    store: Path,
    fit: str | None,
    tags: list[str],
    out: Path,
    bench: Path | None = None,
    animate: Path | None = None,
) -> Path:
    from .site import check_out_dir

    check_out_dir(out)
    if animate is not None:
        from .animate_site import load_animate, write_animate_site

        return write_animate_site(load_animate(store, animate), out)
    if bench is not None:
        from .bench_site import bench_fits, write_bench_site

        rows = bench_fits(store, bench)
        with _progress() as bar:
            return write_bench_site(store, bench, rows, out, bar)
    if fit is not None:
        from .fit_data import load_fit_view
        from .site import write_fit_site

        with _progress() as bar:
            view = load_fit_view(store, fit, progress=bar("reprojecting the fitted character"))
            return write_fit_site(view, out, progress=bar("writing frames"))
    from .gallery import load_gallery, write_bank_site

    with _progress() as bar:
        entries = load_gallery(store, tags, progress=bar("rendering turntables"))
        return write_bank_site(entries, out, tags, progress=bar("writing the gallery"))


@contextmanager
def _progress():
    """``bar(description)`` gives a ``progress(done, total)`` callback for one bar, cleared at the end."""
    from zooctl.cli._common import stage_progress

    with stage_progress(True, transient=True) as update:
        yield lambda description: partial(update, description)


def _serve(site: Path, host: str, port: int, no_browser: bool, what: str) -> None:
    from zooctl.cli._common import console, err_console

    from .serve import is_loopback, make_server, url_of

    server = make_server(site, host, port)
    url = url_of(server, host)
    if not is_loopback(host):
        err_console.print(
            f"[bold yellow]warning:[/] serving on {host}: anyone who can reach this machine on port "
            f"{server.server_address[1]} can open {what} (there is no login). Use the default "
            "--host 127.0.0.1 to keep it to this machine.",
            highlight=False,
        )
    console.print(f"serving {what} at {url}  (Ctrl-C to stop)", highlight=False)
    console.file.flush()
    if not no_browser:
        webbrowser.open(url)
    # A `kill` (SIGTERM) stops it as Ctrl-C does, so the temporary site is removed either way.
    previous = signal.signal(signal.SIGTERM, _interrupt)
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        console.print("stopped")
    finally:
        signal.signal(signal.SIGTERM, previous)
        server.server_close()


def _interrupt(_signum, _frame):
    raise KeyboardInterrupt
