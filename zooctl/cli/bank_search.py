"""`zooctl bank search` and `zooctl bank reindex`: video-to-template retrieval."""

from __future__ import annotations

from pathlib import Path

import typer

from . import batch_opts
from ._common import DeviceOpt, JsonOpt, console, err_console, open_bank, print_json, print_table, store_root


def search(
    video: str = typer.Argument(
        ...,
        help="Video file, folder of frames, DAVIS folder (JPEGImages/ + Annotations/), or a stored video name.",
    ),
    top: int = typer.Option(5, "--top", help="How many assets to list."),
    embedder: list[str] = typer.Option(
        None, "--embedder", help="Embedder to use (repeatable; default: effnet and silhouette)."
    ),
    frames: int = typer.Option(8, "--frames", help="Query frames sampled evenly over the video."),
    masks: Path = typer.Option(
        None, "--masks", help="Folder of mask images, one per frame (DAVIS folders bring their own)."
    ),
    aggregation: str = typer.Option("nearest", "--aggregation", help="nearest (CASA), kmin, min or mean."),
    fusion: str = typer.Option("zsum", "--fusion", help="How embedders combine: zsum, sum or rank."),
    gallery: Path = typer.Option(
        None, "--gallery", help="Write a PNG of the query frames beside the best views of the top assets."
    ),
    explain: bool = typer.Option(
        False,
        "--explain",
        help="Show per-embedder scores of the top results: distance, rank by that embedder alone, "
        "and its term of the fused score.",
    ),
    semantic_weight: float = typer.Option(
        None,
        "--semantic-weight",
        help="Weight of the semantic term: what the video shows (ImageNet classes) against each asset's "
        "animal label (default: the one chosen leave-one-out; 0: appearance only).",
        show_default=False,
    ),
    device: str = DeviceOpt,
    json_out: bool = JsonOpt,
) -> None:
    """Rank the bank's assets by how much their rendered views look like the animal in VIDEO
    (the JSON output always carries the per-embedder terms and ranks that --explain shows)."""
    from ..errors import UsageError
    from ..retrieval.index import enabled_embedders
    from ..retrieval.search import search_source

    if top < 1:  # before the slow part
        raise UsageError(f"--top {top} must be at least 1")
    bank = open_bank()
    query, res = search_source(
        bank,
        video,
        list(embedder) if embedder else enabled_embedders(),
        top=top,
        frames=frames,
        masks_dir=masks,
        store_root=store_root(),
        device=device,
        need_images=gallery is not None,
        aggregation=aggregation,
        fusion=fusion,
        semantic_weight=semantic_weight,
    )
    if gallery is not None:
        from ..retrieval.gallery import save_gallery

        save_gallery(gallery, bank, query, res)
    if json_out:
        out = res.to_json()
        out["query"] = {
            "source": query.source,
            "frames": query.frames.tolist(),
            "masks": query.masks is not None,
        }
        out["gallery"] = None if gallery is None else str(gallery)
        print_json(out)
        return
    for n in res.notes:
        err_console.print(f"[yellow]note:[/] {n}", highlight=False)
    cols = [("rank", "right"), ("asset", "left"), ("label", "left"), ("score", "right")]
    cols += [(e, "right") for e in res.embedders]
    rows = [
        [str(i + 1), m.name, m.label or "-", f"{m.score:.3f}"]
        + [f"{m.distances[e]:.3f}" for e in res.embedders]
        for i, m in enumerate(res.matches)
    ]
    print_table(
        cols,
        rows,
        title=f"best matches of {len(res.matches)} among {res.candidates} assets (score: fused {res.fusion}, lower is better; embedder columns: {res.aggregation} cosine distance)",
    )
    if explain:
        from ..retrieval.explain import explain_lines, explain_table

        ecols, erows, etitle = explain_table(res)
        print_table(ecols, erows, title=etitle)
        for line in explain_lines(res):
            console.print(line, highlight=False, markup=False)
    if gallery is not None:
        console.print(f"gallery: {gallery}", highlight=False, markup=False)


@batch_opts.with_batch_options
def reindex(
    names: list[str] = typer.Argument(None, help="Assets to re-render (default: every asset)."),
    embedder: list[str] = typer.Option(
        None,
        "--embedder",
        help="Embedders to embed the views with (repeatable; default: ZOOCTL_EMBEDDERS or effnet and "
        "silhouette). The asset's other embedders' views are kept.",
    ),
    views: int = typer.Option(24, "--views", help="Views rendered per asset."),
    size: int = typer.Option(224, "--size", help="View size in pixels."),
    missing: bool = typer.Option(
        False, "--missing", help="Only assets that have no views (or lack one of the embedders)."
    ),
    device: str = DeviceOpt,
    json_out: bool = JsonOpt,
    batch: batch_opts.BatchOptions = batch_opts.BatchOpts,
) -> None:
    """Render and embed the retrieval views of bank assets (done by `bank add` for new ones)."""
    from rich.markup import escape

    from ..errors import UsageError, ZooctlError
    from ..retrieval.index import enabled_embedders, index_asset, views_entries

    bank = open_bank()
    targets = list(names) if names else bank.names()
    embs = list(embedder) if embedder else enabled_embedders()
    if missing:
        have = views_entries(bank)
        targets = [n for n in targets if n not in have or not set(embs) <= set(have[n].get("embedders", {}))]
    if batch.executor is not None:  # a batch: render and embed in workers, stored here
        from .bank_many import reindex_many

        return reindex_many(targets, embs, views, size, device, json_out=json_out, batch=batch)
    report, failed = [], []
    for n in targets:
        try:
            asset = bank.get(n)
            entry = index_asset(bank, asset, embs, n_views=views, size=size, device=device)
            report.append({"name": n, "ok": True, "views": entry})
            if not json_out:
                console.print(
                    f"indexed {escape(n)}: {entry['count']} views, {', '.join(entry['embedders'])}",
                    highlight=False,
                )
        except ZooctlError as exc:
            if len(targets) == 1:
                raise
            failed.append(n)
            report.append({"name": n, "ok": False, "error": exc.message})
            err_console.print(f"[bold red]error:[/] {escape(n)}: {escape(exc.message)}", highlight=False)
    if json_out:
        print_json(report)
    if failed:
        raise UsageError(
            f"{len(failed)} of {len(targets)} assets were not indexed",
            hint="fix the errors above and run reindex for them",
        )


def register(app: typer.Typer) -> None:
    """Add `search` and `reindex` to the `bank` group."""
    app.command("search")(search)
    app.command("reindex")(reindex)
