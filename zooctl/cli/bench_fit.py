"""`zooctl bench make` and `zooctl bench run`: CASA's benchmark on videos rendered from bank assets."""

from __future__ import annotations

from pathlib import Path

import typer

from . import batch_opts
from ._common import (
    ArticulationOpt,
    ConfigDeviceOpt,
    FitConfigOpt,
    JsonOpt,
    PresetOpt,
    RendererOpt,
    console,
    err_console,
    print_json,
    store_root,
)


def _assets(bank_path: Path | None, names: list[str] | None):
    """(name, loader) pairs from a store's bank or a folder of model files."""
    from ..errors import InputError

    if bank_path is None or (bank_path / "bank" / "index.json").is_file():
        from ..store.bank import Bank

        bank = Bank.open(bank_path or store_root())
        chosen = names or bank.names()
        return [(n, (lambda n=n: bank.get(n))) for n in chosen]
    if bank_path.is_dir():
        from ..names import sanitize_name
        from ..pipelines.bank_import import import_file

        files = sorted(p for p in bank_path.rglob("*") if p.suffix.lower() in (".glb", ".gltf"))
        if names:
            files = [p for p in files if sanitize_name(p.stem) in names]
        if not files:
            raise InputError(f"{bank_path} holds no .glb/.gltf files and is not a store")
        return [(sanitize_name(p.stem), (lambda p=p: import_file(p, sanitize_name(p.stem)))) for p in files]
    raise InputError(f"--bank {bank_path} is not a store or a folder of models")


def make(
    out: Path = typer.Option(..., "--out", help="Folder for the videos (one subfolder per asset)."),
    bank: Path = typer.Option(
        None, "--bank", help="A store root or a folder of .glb files (default: this store's bank)."
    ),
    asset: list[str] = typer.Option(None, "--asset", help="Only these assets (repeatable)."),
    frames: int = typer.Option(60, "--frames", help="Frames per video."),
    size: int = typer.Option(320, "--size", help="Image size in pixels (square)."),
    seed: int = typer.Option(0, "--seed", help="Random seed."),
    fov: float = typer.Option(
        40.0,
        "--fov",
        help="The camera's vertical field of view in degrees: a fit of a video without its "
        "intrinsics (`bench/user_path.py`) estimates it.",
    ),
    motion: str = typer.Option(
        "random",
        "--motion",
        help="random: 8 random bones re-posed every 12 frames, the rest held; clips: one of the "
        "asset's own clips, in place (random for an asset without clips).",
    ),
    appearance: str = typer.Option(
        "flat",
        "--appearance",
        help="flat: the asset's colours, flat-shaded over a colour gradient; textured: a procedural coat "
        "over a natural-looking scene, and the held-out cameras' frames, so `bench run` reports the "
        "fit's colour error (PSNR) from them.",
    ),
    background: str = typer.Option(
        "still",
        "--background",
        help="still: the background image fixed in the frame, as if the animal turned before a backdrop; "
        "world: a distant natural scene fixed in the world, moving in the frame as the camera orbits "
        "(what a real camera sees; the fit's `camera.motion background` reads the camera's turn from it).",
    ),
    turn: float = typer.Option(
        0.0,
        "--turn",
        help="Degrees the animal turns in the world over the clip, steadily, about the vertical "
        "(the sign drawn by the seed), as an animal walking a bend does; 0: it holds its heading.",
    ),
) -> None:
    """Render PlanetZoo-style test videos with ground truth (motion, camera, masks, flow)."""
    from ..benchdata.make import make_video

    for _name, load in _assets(bank, asset):
        dest = make_video(
            load(),
            out,
            frames=frames,
            size=size,
            seed=seed,
            motion=motion,
            appearance=appearance,
            fov=fov,
            background=background,
            turn=turn,
        )
        console.print(f"made {dest}", highlight=False, markup=False)


@batch_opts.with_batch_options
def run(
    folder: Path = typer.Argument(..., help="Folder made by `zooctl bench make`."),
    preset_name: str = PresetOpt,
    ablation: list[str] = typer.Option(
        None,
        "--ablation",
        help="full, no-flow, no-symmetry, no-smoothness, no-stretch, no-displacement, fixed-skinning, retrieval-only, shape-kept (the template's shape, bones and skinning kept, as fit --keep-shape; repeatable).",
    ),
    template: str = typer.Option(
        None, "--template", help="Fit every video with this bank asset instead of retrieval."
    ),
    limit: int = typer.Option(None, "--limit", help="Only the first N videos."),
    own_template: bool = typer.Option(
        False,
        "--own-template",
        help="Fit each video with its own asset (no retrieval): what a bank that holds the animal allows.",
    ),
    known_camera: bool = typer.Option(
        False,
        "--known-camera",
        help="Give each fit its video's camera rotations (CASA's protocol on synthetic data) instead of estimating the camera's motion.",
    ),
    pose_prior: str = typer.Option(
        None,
        "--pose-prior",
        help="Pose prior of every fit: none, rest (rotations near the rest pose), clips (the template's clip statistics) or motion (the store's latest motion prior scores the fitted motion; another one: --config); default: the preset's.",
    ),
    renderer: str = RendererOpt,
    articulation: str = ArticulationOpt,
    device: str | None = ConfigDeviceOpt,
    config: Path = FitConfigOpt,
    report: Path = typer.Option(None, "--report", help="Also write the markdown table here."),
    json_out: bool = JsonOpt,
    batch: batch_opts.BatchOptions = batch_opts.BatchOpts,
    resume: bool = typer.Option(
        False, "--resume", help="Keep the fits a previous run of this benchmark finished (runs as a batch)."
    ),
) -> None:
    """Fit every benchmark video (its own asset excluded from retrieval) and report CASA's metrics,
    how many templates have the video's body plan, and the metrics by that plan (the lowest novel view
    first). Each fit's folder in the store (`zooctl fits show NAME`) gets novel_view.png: the fit
    against the truth from the cameras it never saw."""
    from ..benchdata.run import markdown_table, run_benchmark
    from ..store.fs import write_bytes_atomic

    def progress(row):
        if "error" in row:
            err_console.print(
                f"{row['video']} [{row['ablation']}]: error: {row['error']}", highlight=False, markup=False
            )
        else:
            err_console.print(
                f"{row['video']} [{row['ablation']}]: template {row['template']}, mask IoU {row['mask_iou']:.3f}, "
                f"novel-view IoU {_num(row.get('novel_view_iou'))}, {row['wall_s']:.0f} s",
                highlight=False,
                markup=False,
            )

    if device is not None:  # up front: else every fit would fail the same way
        from ..fit.run import check_device

        check_device(device)
    args = (folder, store_root(), preset_name, list(ablation) if ablation else None, template, limit)
    opts = dict(
        known_camera=known_camera,
        own_template=own_template,
        overrides=config_overrides(config, component_overrides(renderer, articulation, pose_prior, device)),
    )
    if batch.executor is not None or resume:  # a batch: each fit one task
        from ..benchdata.run import bench_videos

        fits = len(bench_videos(Path(folder))[: limit or None]) * max(1, len(ablation or ()))
        ex = batch.make_executor(device, fits=fits)
        from ..pipelines.batch import BatchInterrupted

        try:
            with batch_opts.RichBatchProgress(enabled=not json_out) as prog:
                res = run_benchmark(*args, executor=ex, resume=resume, batch_progress=prog, **opts)
        except BatchInterrupted as exc:
            batch_opts.say_interrupted(exc.report, None)
            raise typer.Exit(batch_opts.stop_code(exc)) from None
        finally:
            ex.close()
    else:
        res = run_benchmark(*args, progress=progress, **opts)
    table = markdown_table(res)
    if report is not None:
        write_bytes_atomic(report, table.encode())
    if json_out:
        print_json(res)
    else:
        console.file.write(table)
    failed = [r for r in res["rows"] if "error" in r]
    if failed and (batch.executor is not None or resume):
        from ..errors import UsageError

        raise UsageError(
            f"{len(failed)} of {len(res['rows'])} benchmark fits failed (see the table)",
            hint="run again with --resume to redo only those",
        )


def _num(x: float | None) -> str:
    return "n/a" if x is None else f"{x:.3f}"


def component_overrides(
    renderer: str | None, articulation: str | None, pose_prior: str | None = None, device: str | None = None
) -> dict | None:
    """Config overrides naming registered components, the pose prior or the device (checked when the
    config is validated)."""
    out: dict = {} if device is None else {"device": device}
    if pose_prior is not None:
        out["pose_prior"] = {"kind": pose_prior}
    if renderer is not None:
        out["stage1"] = {"renderer": renderer}
        out["stage2"] = {"renderer": renderer}
    if articulation is not None:
        out["articulation"] = articulation
    return out or None


def config_overrides(path: Path | None, flags: dict | None) -> dict | None:
    """A `--config` file's fields with the component flags' on top (nested dicts merged)."""
    if path is None:
        return flags
    from ..errors import UsageError
    from ..fit.config import read_config_file

    data = read_config_file(path)
    if not isinstance(data, dict):
        raise UsageError(f"config file {path} must hold a JSON object of config fields")
    if "preset" in data:
        raise UsageError(f"config file {path} sets the preset", hint="choose it with --preset")

    def merge(a: dict, b: dict) -> dict:
        out = dict(a)
        for k, v in b.items():
            out[k] = merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
        return out

    return merge(data, flags or {}) or None


def register(app: typer.Typer) -> None:
    app.command("make")(make)
    app.command("run")(run)
