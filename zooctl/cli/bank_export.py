"""`zooctl bank export`: a bank asset through any registered exporter (`zooctl.io.asset_export`)."""

from __future__ import annotations

import typer

from ._common import JsonOpt, console, open_bank, print_json


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
    output: str = typer.Option(
        None,
        "--output",
        "-o",
        help="File, or folder (an existing one, or any path ending in /). Default: NAME.suffix here.",
    ),
    camera: bool = typer.Option(
        False, "--camera", help="USD only: add a camera (/Camera) framing the clips."
    ),
    json_out: bool = JsonOpt,
) -> None:
    """Export a bank asset (skeleton, skin, clips) as USD, glTF (.glb), BVH or a plugin's format."""
    import time

    from ..errors import UsageError
    from ..io.asset_export import export_asset, prepare_export

    if clip and all_clips:
        raise UsageError("--clip and --all-clips cannot be used together", hint="drop one of them")
    asset = open_bank().get(name)
    spec, fmt, path = prepare_export(output, fmt, name, default_format="usdz")
    t0 = time.perf_counter()
    options = {}
    if camera:
        if spec.name != "usd":
            raise UsageError("--camera is for USD exports", hint="drop --camera, or export usd/usda/usdz")
        import numpy as np

        from ..render.preview import fit_camera

        names = list(clip) if clip else list(asset.clips)
        # Each pose's bounding box, of at most 64 frames a clip: a long clip's poses are not held.
        poses = [(None, None)]
        for c in (c for c in names if c in asset.clips):
            n = asset.clips[c].num_frames
            picked = np.unique(np.linspace(0, n - 1, min(n, 64)).round().astype(int))
            poses += [(c, picked[s : s + 8]) for s in range(0, len(picked), 8)]
        posed = (asset.pose(c, idx).reshape(-1, asset.num_vertices, 3) for c, idx in poses)
        corners = [np.stack([p.min(1), p.max(1)], 1).reshape(-1, 3) for p in posed]
        options["camera"] = fit_camera(np.concatenate(corners), 720, 1280)
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


def register(app: typer.Typer) -> None:
    app.command("export")(export)
