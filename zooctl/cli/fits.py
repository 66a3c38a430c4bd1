"""`zooctl fits ...`: the fits in the store."""

from __future__ import annotations

import typer

from ._common import APP_OPTS, JsonOpt, console, print_json, print_skipped, print_table, store_root

app = typer.Typer(**APP_OPTS, help="List, show, export and remove fits.", no_args_is_help=True)


def _fits():
    from ..store.fits import FitStore

    return FitStore(store_root())


@app.command("list")
def list_(json_out: bool = JsonOpt) -> None:
    """Every fit: status, template, frames, mask IoU."""
    recs, skipped = _fits().records()
    print_skipped(skipped, "not listed")
    if json_out:
        print_json(
            [
                {k: r.get(k) for k in ("name", "status", "template", "frames", "source", "metrics")}
                for r in recs
            ]
        )
        return
    rows = []
    for r in recs:
        iou = (r.get("metrics") or {}).get("mask_iou")
        rows.append(
            [
                r["name"],
                r.get("status", "?"),
                r.get("template", ""),
                str(r.get("frames", "")),
                "" if iou is None else f"{iou:.3f}",
            ]
        )
    print_table(
        [
            ("name", "left"),
            ("status", "left"),
            ("template", "left"),
            ("frames", "right"),
            ("mask IoU", "right"),
        ],
        rows,
    )


@app.command("show")
def show(name: str = typer.Argument(...), json_out: bool = JsonOpt) -> None:
    """One fit's record."""
    rec = _fits().get(name)
    if json_out:
        print_json(rec)
        return
    for k in ("name", "status", "source", "template", "frames", "image_size", "out"):
        console.print(f"{k}: {rec.get(k)}", highlight=False, markup=False)
    for k, v in (rec.get("metrics") or {}).items():
        if not isinstance(v, list):
            console.print(f"metric {k}: {v}", highlight=False, markup=False)
    for k, v in (rec.get("outputs") or {}).items():
        console.print(f"output {k}: {v}", highlight=False, markup=False)


@app.command("export")
def export(
    name: str = typer.Argument(...),
    out: str = typer.Option(
        ...,
        "--out",
        metavar="PATH",
        help="File to write (its suffix picks the format unless --format), or a folder (an existing one, or any path ending in /).",
    ),
    fmt: str = typer.Option(
        None, "--format", help="Any registered exporter's format: usd, usda, usdz, glb, bvh, a plugin's."
    ),
) -> None:
    """Export a fitted character (rig, skin and the per-frame animation) through an exporter."""
    from ..io.asset_export import export_asset, prepare_export

    asset = _fits().character(name)
    _, fmt, path = prepare_export(out, fmt, name)
    path = export_asset(asset, path, fmt)
    console.print(f"wrote {path}", highlight=False, markup=False)


@app.command("rm")
def rm(name: str = typer.Argument(...)) -> None:
    """Remove a fit (its record, state and the outputs in its store folder)."""
    _fits().remove(name)
    console.print(f"removed {name}", highlight=False, markup=False)
