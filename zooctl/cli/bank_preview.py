"""`zooctl bank render`: shaded previews of bank assets (stills, clip videos, contact sheets)."""

from __future__ import annotations

from pathlib import Path

import typer

from ._common import JsonOpt, console, open_bank, print_json


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
    from ..render.preview import contact_sheet, render_asset, render_asset_frames, save_png

    bank = open_bank()
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
        frames = render_asset_frames(asset, c, size=size, azimuth=azimuth, elevation=elevation)
        write_mp4(out, frames, fps=asset.clips[c].fps)  # written as rendered: a long clip is not held
        _report(json_out, {"path": str(out), "clip": c, "frames": asset.clips[c].num_frames})
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
    app.command("render")(render)
