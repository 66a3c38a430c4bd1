"""`zooctl bench retrieval`: leave-one-out retrieval accuracy over a set of assets."""

from __future__ import annotations

from pathlib import Path

import typer

from ._common import DeviceOpt, JsonOpt, err_console, print_json, print_table


def retrieval(
    assets: Path = typer.Option(
        None, "--assets", help="Folder searched for .glb/.gltf files (default: ../shared/data/assets)."
    ),
    starter: bool = typer.Option(
        False, "--starter", help="Use the procedural starter bank instead of model files."
    ),
    with_starter: bool = typer.Option(
        False,
        "--with-starter",
        help="Also put the procedural starter animals in the bank (queries stay the model files).",
    ),
    embedder: list[str] = typer.Option(
        None, "--embedder", help="Embedders (repeatable; default: effnet and silhouette)."
    ),
    views: int = typer.Option(24, "--views", help="Views rendered per bank asset."),
    frames: int = typer.Option(8, "--frames", help="Frames per rendered query video."),
    limit: int = typer.Option(0, "--limit", help="Use only the first N assets (0: all)."),
    device: str = DeviceOpt,
    json_out: bool = JsonOpt,
) -> None:
    """Leave-one-out: render a query video of each asset, search the bank without it, score body plans."""
    import tempfile

    from ..errors import InputError
    from ..retrieval.benchmark import COLUMNS, loo_benchmark, summary_rows

    if starter:
        from ..procedural import starter_assets

        items = starter_assets()
    else:
        from ..io.gltf_import import load_gltf

        folder = assets or Path(__file__).resolve().parents[3] / "shared" / "data" / "assets"
        files = sorted([*folder.rglob("*.glb"), *folder.rglob("*.gltf")]) if folder.is_dir() else []
        if not files:
            raise InputError(f"no .glb/.gltf files under {folder}", hint="pass --assets DIR or --starter")
        items = [load_gltf(f, f.stem) for f in files]
    if limit:
        items = items[:limit]
    queries = None
    if with_starter and not starter:
        from ..procedural import starter_assets

        queries = [a.name for a in items]
        items = items + starter_assets()
    if len(items) < 2:
        raise InputError("leave-one-out needs at least 2 assets")
    with tempfile.TemporaryDirectory(prefix="zooctl-bench-retrieval-") as tmp:
        report = loo_benchmark(
            items,
            Path(tmp),
            list(embedder) if embedder else ["effnet", "silhouette"],
            n_views=views,
            frames=frames,
            device=device,
            queries=queries,
            progress=None
            if json_out
            else (lambda msg, i, n: err_console.print(f"[{i}/{n}] {msg}", highlight=False)),
        )
    if json_out:
        print_json(report)
        return
    print_table(
        COLUMNS,
        summary_rows(report),
        title=f"leave-one-out: {report['queries']} queries, bank of {report['assets']} assets ({views} views, {frames} query frames)",
    )


def register(app: typer.Typer) -> None:
    app.command("retrieval")(retrieval)
