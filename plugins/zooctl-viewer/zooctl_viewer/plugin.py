"""Registers `zooctl view`. Everything heavy (torch, the store, the site) is imported when it runs."""

from __future__ import annotations

from pathlib import Path

import typer

from zooctl.plugins import hookimpl


@hookimpl
def register_commands(cli):
    @cli.command("view")
    def view(
        fit: str = typer.Argument(None, help="Fit to show (a name from `zooctl fits list`)."),
        bank: bool = typer.Option(False, "--bank", help="Show the bank as a gallery instead of a fit."),
        bench: Path = typer.Option(
            None,
            "--bench",
            help="Show the benchmark table of `zooctl bench run DIR` (this benchmark folder), each row opening its fit.",
        ),
        animate: Path = typer.Option(
            None,
            "--animate",
            help="Show the motions `zooctl animate` sampled into this folder beside the character's real clip.",
        ),
        tag: list[str] = typer.Option(
            None, "--tag", help="With --bank: only assets with this tag (repeat for several)."
        ),
        export: Path = typer.Option(
            None, "--export", help="Write a static site to this folder (opens from disk) instead of serving."
        ),
        host: str = typer.Option(
            "127.0.0.1", "--host", help="Address to serve on; another than 127.0.0.1 exposes the page."
        ),
        port: int = typer.Option(8765, "--port", min=0, max=65535, help="Port (0: any free one)."),
        no_browser: bool = typer.Option(False, "--no-browser", help="Do not open a browser."),
    ) -> None:
        """Look at a fit in 3D in a browser: the character beside its video, masks and silhouette,
        frame slider, skeleton, the input camera and free views, retrieval and metrics. --bank
        shows the bank as a gallery, --bench DIR a benchmark's table, --animate DIR sampled motions."""
        from .command import run_view

        run_view(fit, bank, tag or [], export, host, port, no_browser, bench, animate)
