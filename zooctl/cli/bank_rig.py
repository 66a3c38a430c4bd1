"""`zooctl bank export | seed | render`: rig export, the procedural starter bank, previews."""

from __future__ import annotations

from pathlib import Path

import typer

from ._common import JsonOpt, console, print_json, stage_progress, store_root


def _bank():
    from ..store.bank import Bank

    return Bank.open(store_root())


def export(
    name: str = typer.Argument(..., help="Asset name in the bank."),
    fmt: str = typer.Option(
        None,
        "--format",
        "-f",
        help="Any registered exporter's format: usd (binary), usda (text), usdc, usdz, glb, bvh, or a "
        "plugin's (`zooctl plugins`). Default: from -o, else usdz.",
    ),
    clip: list[str] = typer.Option(None, "--clip", help="Export only this clip (repeatable)."),
    all_clips: bool = typer.Option(
        False, "--all-clips", help="Export every clip (the default when no --clip is given)."
    ),
    output: Path = typer.Option(
        None,
        "--output",
        "-o",
        help="File to write, or an existing folder to write NAME plus the format's suffix into. Default: NAME plus the suffix.",
    ),
    camera: bool = typer.Option(
        False, "--camera", help="USD only: add a camera (/Camera) framing the clips."
    ),
    json_out: bool = JsonOpt,
) -> None:
    """Export a bank asset with its skeleton, skin and clips through an exporter: USD (UsdSkel),
    glTF (.glb), BVH (skeleton and motion) or a plugin's format."""
    import time

    from ..errors import UsageError
    from ..io.export import check_writable, export_asset, resolve_export

    if clip and all_clips:
        raise UsageError("--clip and --all-clips cannot be used together", hint="drop one of them")
    spec, fmt, path = resolve_export(output, fmt, name, default_format="usdz")
    check_writable(path)
    asset = _bank().get(name)
    t0 = time.perf_counter()
    options = {}
    if camera:
        if spec.name != "usd":
            raise UsageError("--camera is for USD exports", hint="drop --camera, or export usd/usda/usdz")
        import numpy as np

        from ..render.preview import fit_camera

        names = list(clip) if clip else list(asset.clips)
        pts = [asset.pose(None)]
        pts += [
            asset.pose(c, np.arange(asset.clips[c].num_frames)).reshape(-1, 3)
            for c in names
            if c in asset.clips
        ]
        options["camera"] = fit_camera(np.concatenate(pts), 720, 1280)
    path = export_asset(asset, path, fmt, list(clip) if clip else None, **options)
    seconds = time.perf_counter() - t0
    clips = list(clip) if clip else list(asset.clips)
    if json_out:
        print_json(
            {
                "name": name,
                "format": fmt,
                "path": str(path),
                "clips": clips,
                "bytes": path.stat().st_size,
                "seconds": round(seconds, 3),
            }
        )
    else:
        console.print(
            f"wrote {path} ({fmt}, {len(clips)} clips, {path.stat().st_size / 1e6:.2f} MB)",
            highlight=False,
            markup=False,
        )


def seed(
    seed_value: int = typer.Option(
        0, "--seed", help="Random seed for proportions and colours (same seed, same animals)."
    ),
    plan: list[str] = typer.Option(
        None,
        "--plan",
        help="Only this body plan (repeatable): quadruped, biped, bird, fish, snake, insect, spider.",
    ),
    no_variants: bool = typer.Option(
        False, "--no-variants", help="One animal per plan, without the proportion variants."
    ),
    replace: bool = typer.Option(False, "--replace", help="Overwrite starter animals already in the bank."),
    views: bool = typer.Option(
        None,
        "--views/--no-views",
        help="Render and embed retrieval views of the added animals (default: on; ZOOCTL_VIEWS=0 turns "
        "the default off).",
        show_default=False,
    ),
    json_out: bool = JsonOpt,
) -> None:
    """Add the procedural starter animals (rigged, skinned, animated; generated, nothing downloaded)."""
    from ..pipelines.ingest import seed_starter

    bank = _bank()
    with stage_progress(not json_out) as progress:
        added = seed_starter(
            bank,
            seed=seed_value,
            plans=list(plan) if plan else None,
            variants=not no_variants,
            replace=replace,
            views=views,
            progress=progress,
        )
    if json_out:
        print_json({"added": added, "bank_size": len(bank.names())})
    else:
        console.print(
            f"added {len(added)} starter animals"
            + (f": {', '.join(added)}" if added else " (all present; --replace to rebuild)"),
            highlight=False,
            markup=False,
        )


def render(
    name: str = typer.Argument(None, help="Asset to render (omit with --sheet)."),
    clip: str = typer.Option(
        None,
        "--clip",
        help="Clip to pose (a video plays it; a still shows --frame). Default for videos: the first clip.",
    ),
    frame: int = typer.Option(0, "--frame", help="Clip frame of a still image."),
    output: Path = typer.Option(
        None,
        "--output",
        "-o",
        help=".png still or contact sheet, or .mp4 video (H.264). Default: NAME.png / bank.png.",
    ),
    sheet: bool = typer.Option(
        False, "--sheet", help="A contact sheet of every asset in the bank (or those with --tag)."
    ),
    tag: str = typer.Option(None, "--tag", help="With --sheet: only assets with this tag."),
    size: int = typer.Option(256, "--size", min=32, max=2048, help="Image height (and width) in pixels."),
    azimuth: float = typer.Option(
        30.0,
        "--azimuth",
        help="Camera angle around the vertical, degrees from the animal's right side towards its front.",
    ),
    elevation: float = typer.Option(18.0, "--elevation", help="Camera angle above the horizon, degrees."),
    json_out: bool = JsonOpt,
) -> None:
    """Render shaded previews on the CPU: a still, a clip video, or a contact sheet of the bank."""
    from ..errors import UsageError
    from ..render.preview import contact_sheet, render_asset, save_png

    bank = _bank()
    if sheet:
        if name is not None:
            raise UsageError(
                "--sheet renders the whole bank; give no NAME with it", hint="use --tag to choose assets"
            )
        out = output or Path("bank.png")
        if out.suffix.lower() != ".png":
            raise UsageError("a contact sheet is a .png image", hint="use -o sheet.png")
        rows = [r for r in bank.list() if tag is None or tag in r.get("tags", [])]
        if not rows:
            raise UsageError(
                "no assets to put on a contact sheet",
                hint="add some with `zooctl bank seed` or `zooctl bank add`",
            )
        images, labels = [], []
        for r in rows:
            asset = bank.get(r["name"])
            c = next(iter(asset.clips), None)
            frames = None if c is None else [asset.clips[c].num_frames // 3]
            images.append(render_asset(asset, c, frames, size=size, azimuth=azimuth, elevation=elevation)[0])
            labels.append(r["name"])
        save_png(out, contact_sheet(images, labels))
        _report(json_out, {"path": str(out), "assets": labels})
        return
    if name is None:
        raise UsageError("give an asset NAME, or --sheet for the whole bank")
    asset = bank.get(name)
    out = output or Path(f"{name}.png")
    suffix = out.suffix.lower()
    if suffix == ".mp4":
        from ..io.video import write_mp4

        c = clip or next(iter(asset.clips), None)
        if c is None:
            raise UsageError(
                f"asset {name!r} has no clips to make a video of", hint="render a still (.png) instead"
            )
        frames = render_asset(asset, c, size=size, azimuth=azimuth, elevation=elevation)
        write_mp4(out, frames, fps=asset.clips[c].fps)
        _report(json_out, {"path": str(out), "clip": c, "frames": len(frames)})
    elif suffix == ".png":
        if clip is not None and clip in asset.clips and not (0 <= frame < asset.clips[clip].num_frames):
            raise UsageError(
                f"--frame {frame} is outside clip {clip!r} (0..{asset.clips[clip].num_frames - 1})"
            )
        img = render_asset(
            asset, clip, None if clip is None else [frame], size=size, azimuth=azimuth, elevation=elevation
        )[0]
        save_png(out, img)
        _report(json_out, {"path": str(out), "clip": clip, "frame": frame if clip else None})
    else:
        raise UsageError(
            f"cannot render to {out.name!r}", hint="use a .png (still) or .mp4 (video) file name"
        )


def _report(json_out: bool, info: dict) -> None:
    if json_out:
        print_json(info)
    else:
        console.print(f"wrote {info['path']}", highlight=False, markup=False)


def register(app: typer.Typer) -> None:
    """Add `export`, `seed` and `render` to the `bank` command group."""
    app.command("export")(export)
    app.command("seed")(seed)
    app.command("render")(render)
