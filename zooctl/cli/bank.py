"""`zooctl bank ...`: the rigged-asset bank."""

from __future__ import annotations

from pathlib import Path

import typer

from . import batch_opts
from ._common import (
    APP_OPTS,
    JsonOpt,
    ViewsOpt,
    add_rm_command,
    add_upkeep_commands,
    console,
    err_console,
    open_bank,
    print_json,
    print_listing,
    print_skipped,
    print_views_pending,
    stage_progress,
)

app = typer.Typer(
    **APP_OPTS,
    help="Manage the bank of rigged, animated assets (templates for fitting).",
    no_args_is_help=True,
)


def _limit_option(key: str, refuse: str):
    """A `bank add --max-*` option: None keeps the import limit ``key`` of `zooctl.limits`."""
    from ..limits import DEFAULT, OPTION

    return typer.Option(
        None, OPTION[key], help=f"{refuse} (default: {getattr(DEFAULT, key):.0f}).", show_default=False
    )


@app.command("add")
@batch_opts.with_batch_options
def add(
    paths: list[Path] = typer.Argument(
        ..., help="Model files to import (.glb, .gltf, and whatever plugins add)."
    ),
    name: str = typer.Option(
        None, "--name", help="Asset name (default: the file name without suffix). One PATH only."
    ),
    tag: list[str] = typer.Option(None, "--tag", help="Tag to attach (repeatable), e.g. --tag quadruped."),
    license: str = typer.Option(None, "--license", help="License of the asset, e.g. CC0-1.0."),
    label: str = typer.Option(
        None,
        "--label",
        help='What animal it is, e.g. --label "red fox" (default: what its name, tags or rendered '
        "views show; `bank label` changes it).",
    ),
    replace: bool = typer.Option(False, "--replace", help="Overwrite an asset of the same name."),
    views: bool | None = ViewsOpt,
    max_clip_seconds: float = _limit_option(
        "max_clip_seconds", "Refuse a clip longer than this many seconds"
    ),
    max_frames: int = _limit_option("max_frames", "Refuse an asset whose clips have more frames in all"),
    max_vertices: int = _limit_option("max_vertices", "Refuse an asset with more vertices"),
    max_elements: int = _limit_option(
        "max_elements", "Refuse larger arrays: one glTF accessor, or frames x joints of all clips"
    ),
    json_out: bool = JsonOpt,
    batch: batch_opts.BatchOptions = batch_opts.BatchOpts,
    resume: bool = typer.Option(
        False, "--resume", help="Skip files whose asset (and views) the bank holds already (runs as a batch)."
    ),
) -> None:
    """Import rigged assets into the bank (atomic: a failed import changes nothing).

    Limits keep a small broken file from taking gigabytes (a keyframe at t = 1e5 s); raise them
    with the --max-* options for a real asset that needs more."""
    from rich.markup import escape

    from ..errors import UsageError
    from ..limits import import_limits, limits_with
    from ..pipelines.bank_import import add_files

    limits = dict(
        max_clip_seconds=max_clip_seconds,
        max_frames=max_frames,
        max_vertices=max_vertices,
        max_elements=max_elements,
    )
    if batch.executor is not None or resume:  # a batch: import and views in workers, stored here
        from .bank_many import add_many

        opts = dict(
            name=name, tags=tag, license=license, replace=replace, views=views, resume=resume, label=label
        )
        limits_with(**limits)  # a bad value is one error here; the workers apply them
        return add_many(paths, json_out=json_out, limits=limits, batch=batch, **opts)

    with import_limits(**limits), stage_progress(not json_out and len(paths) > 1) as progress:
        results = add_files(
            open_bank(),
            paths,
            name=name,
            tags=tag,
            license=license,
            replace=replace,
            views=views,
            progress=progress,
            label=label,
        )
    failed = [r for r in results if r.error is not None]
    if json_out:
        print_json(
            [
                {
                    "path": str(r.path),
                    "name": r.name,
                    "ok": r.error is None,
                    "error": None if r.error is None else r.error.message,
                    "summary": r.summary,
                }
                for r in results
            ]
        )
    else:
        for r in results:
            if r.summary is not None:
                s = r.summary
                console.print(
                    f"added [bold]{escape(r.name)}[/]: {s['vertices']} vertices, {s['joints']} joints, {len(s['clips'])} clips",
                    highlight=False,
                )
    if len(results) == 1 and failed:
        raise failed[0].error  # one line, with its hint
    for r in failed:
        err_console.print(
            f"[bold red]error:[/] {escape(str(r.path))}: {escape(r.error.message)}",
            highlight=False,
            soft_wrap=True,
        )
    if failed:
        raise UsageError(
            f"{len(failed)} of {len(results)} files were not added",
            hint="the others were added; fix the files named above and add them again",
        )


@app.command("list")
def list_(
    json_out: bool = JsonOpt, tag: str = typer.Option(None, "--tag", help="Only assets with this tag.")
) -> None:
    """List the assets in the bank."""
    bank = open_bank()
    rows = bank.list()
    print_views_pending(bank.views_pending(rows))
    if tag:
        rows = [r for r in rows if tag in r.get("tags", [])]
    what = f"no asset tagged {tag!r} in the bank" if tag else "the bank is empty"

    def cells(r: dict) -> list[str]:
        lo, hi = r["bbox"]
        size = max(h - lo_ for lo_, h in zip(lo, hi))
        counts = [str(r[k]) for k in ("vertices", "faces", "joints")] + [str(len(r["clips"]))]
        return [r["name"], *counts, f"{size:.3g}", r.get("label") or "-", ", ".join(r.get("tags", []))]

    cols = [
        ("name", "left"),
        ("vertices", "right"),
        ("faces", "right"),
        ("joints", "right"),
        ("clips", "right"),
        ("size", "right"),
        ("label", "left"),
        ("tags", "left"),
    ]
    print_listing(
        rows,
        json_out,
        cols,
        cells,
        title=f"{len(rows)} assets",
        empty=f"{what} ({bank.root}): `zooctl bank seed` adds the starter animals, `zooctl bank add FILE` yours",
    )


@app.command("show")
def show(name: str = typer.Argument(..., help="Asset name."), json_out: bool = JsonOpt) -> None:
    """Show one asset: counts, bounding box, clips and the joint tree."""
    card = open_bank().card(name)
    if json_out:
        print_json(card)
        return
    from rich.tree import Tree

    lo, hi = card["bbox"]
    console.print(
        f"[bold]{card['name']}[/]  {card['vertices']} vertices, {card['faces']} faces, {card['joints']} joints, {card['skin_influences']} influences per vertex",
        highlight=False,
    )
    console.print(f"bbox min {[round(x, 4) for x in lo]}  max {[round(x, 4) for x in hi]}", highlight=False)
    if card.get("license"):
        console.print(f"license: {card['license']}", highlight=False)
    if card.get("source"):
        console.print(f"source: {card['source']}", highlight=False)
    if card.get("tags"):
        console.print(f"tags: {', '.join(card['tags'])}", highlight=False)
    console.print(f"label: {_label_line(card)}", highlight=False, markup=False)
    for w in card.get("meta", {}).get("import_warnings", []):
        console.print(f"[yellow]import warning:[/] {w}", highlight=False)
    console.print(f"clips ({len(card['clips'])}):", highlight=False)
    for cname, c in card["clips"].items():
        console.print(f"  {cname}: {c['frames']} frames at {c['fps']:g} fps", highlight=False, markup=False)
    names, parents = card["joint_names"], card["parents"]
    nodes = {}
    tree = Tree("joints")
    for j, (jn, p) in enumerate(zip(names, parents)):
        nodes[j] = (tree if p < 0 else nodes[p]).add(jn, highlight=False)
    console.print(tree)


def _label_line(entry: dict) -> str:
    """ "Shiba Inu (domestic dog > Canidae > Carnivora > quadruped; given)", or why there is none."""
    from ..retrieval.semantic import label_taxon

    label = entry.get("label")
    if not isinstance(label, str):
        return "none (`zooctl bank label NAME` infers one, `bank label NAME LABEL` sets it)"
    taxon = label_taxon(label)
    where = entry.get("label_source", "given")
    return f"{label} ({taxon.lineage() + '; ' if taxon else ''}{where})"


@app.command("label")
def label_cmd(
    name: str = typer.Argument(..., help="Asset name."),
    label: str = typer.Argument(
        None,
        help='What animal it is: a common name ("red fox", "horse") or a body plan ("quadruped"). '
        "Without it, inferred again from the asset's name, tags and rendered views.",
        show_default=False,
    ),
    json_out: bool = JsonOpt,
) -> None:
    """Set or infer what animal an asset is (search ranks assets of the video's animal first)."""
    from ..errors import UsageError
    from ..retrieval.labels import relabel

    bank = open_bank()
    bank.summary(name)  # a missing asset is one clear error before any work
    entry = relabel(bank, name, label)
    if entry is None:
        raise UsageError(
            f"neither the name, the tags nor the rendered views of {name!r} show an animal zooctl knows",
            hint=f'give it one: `zooctl bank label {name} "red fox"`',
        )
    if json_out:
        print_json({"name": name, "label": entry["label"], "label_source": entry["label_source"]})
    else:
        console.print(f"{name}: {_label_line(entry)}", highlight=False, markup=False)


add_rm_command(app, open_bank, "Remove assets from the bank.", "Asset names to remove.")


@app.command("migrate")
def migrate(json_out: bool = JsonOpt) -> None:
    """Upgrade every asset file to this zooctl's layout (named migrations, atomic per asset)."""
    from ..store.migrate import migrate_bank

    report = migrate_bank(open_bank())
    if json_out:
        print_json(report)
    else:
        console.print(
            f"{report['migrated']} assets migrated, {report['current']} already current", highlight=False
        )
        print_skipped(report["skipped"], "left as they are")


def _repair(bank):
    from ..pipelines.bank_import import repair_bank

    return repair_bank(bank)


add_upkeep_commands(
    app,
    open_bank,
    "assets",
    clean_help="""Remove leftovers of killed writers (temporary files; cards and views of removed assets).

Never deletes an asset file: ones the index does not name are listed (`zooctl bank repair`
indexes the valid ones).""",
    repair_help="""Rebuild the bank index from the asset files (after it was lost or damaged).

Every valid asset file is indexed (its retrieval views too, when their sidecar is intact);
invalid files are listed with the reason and left where they are. Missing cards are rewritten.
Assets whose `bank add` stopped before their retrieval views were stored get them rendered.""",
    repair_store=_repair,
)


from . import bank_export, bank_preview, bank_seed  # noqa: E402  (one module per command)

for _mod in (bank_export, bank_seed, bank_preview):
    _mod.register(app)

from . import bank_search  # noqa: E402  (search, reindex: retrieval lives in its own module)

bank_search.register(app)
