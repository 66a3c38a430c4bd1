"""`zooctl fit`: a video of an animal in, a rigged, skinned, animated character out."""

from __future__ import annotations

from pathlib import Path

import typer

from ..fit.config import PRESETS
from . import batch_opts, fit_many
from ._common import (
    ArticulationOpt,
    ConfigDeviceOpt,
    FitConfigOpt,
    PresetOpt,
    RendererOpt,
    console,
    err_console,
    print_json,
    store_root,
)

PRESET_ITERS = {name: make().stage2.iters for name, make in PRESETS.items()}


class RichReporter:
    """A rich progress bar per stage with the live loss terms."""

    def __init__(self) -> None:
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

        self.progress = Progress(
            TextColumn("[bold]{task.fields[stage]}"),
            BarColumn(),
            MofNCompleteColumn(),
            TimeElapsedColumn(),
            TextColumn("{task.fields[loss]}"),
            console=err_console,
            transient=False,
        )
        self.task = None

    def __enter__(self) -> RichReporter:
        self.progress.start()
        return self

    def __exit__(self, *exc) -> None:
        self.progress.stop()

    def stage(self, name: str, total: int, done: int = 0) -> None:
        self.task = self.progress.add_task("", total=total, completed=done, stage=name, loss="")

    def step(self, terms: dict[str, float]) -> None:
        main = ("total", "mask", "flow", "smooth", "symmetry")
        text = "  ".join(f"{k} {terms[k]:.4f}" for k in main if k in terms)
        self.progress.update(self.task, advance=1, loss=text)

    def message(self, text: str) -> None:
        self.progress.console.print(f"[dim]{text}[/]", highlight=False)


@batch_opts.with_batch_options
def fit(
    videos: list[str] = typer.Argument(
        ...,
        help="Video file, image or DAVIS folder (added to the video store first), `bench make` folder, or a stored video name. "
        "Several (or a quoted glob): a batch, one task per video (see --executor).",
    ),
    template: str = typer.Option(
        None,
        "--template",
        help="Bank asset to fit, as a rule the animal's own rig (its joints and shape step at stage2.lr_joints_given and lr_shape_given; default: template retrieval).",
    ),
    keep_shape: bool = typer.Option(
        False,
        "--keep-shape",
        help="The template is the animal's own rig: keep its shape, bone lengths and skinning, and fit "
        "only the pose, the root and the camera (a truer 3D pose; a little less input IoU).",
    ),
    masks: str = typer.Option(
        None, "--masks", help="Folder of mask images (one per frame), or 'auto' (GrabCut)."
    ),
    box: str = typer.Option(
        None,
        "--box",
        help="x,y,w,h around the animal in the first frame (original pixels): chooses the animal --masks auto "
        "segments.",
    ),
    out: Path = typer.Option(
        None,
        "--out",
        help="Output folder (default: fits/NAME in the current folder; a batch: OUT/NAME per video).",
    ),
    name: str = typer.Option(None, "--name", help="Fit name (default: the video's name)."),
    preset_name: str = PresetOpt,
    iters: int = typer.Option(
        None,
        "--iters",
        help=f"Stage 2 iterations (overrides the preset: {', '.join(f'{k} {v}' for k, v in PRESET_ITERS.items())}).",
    ),
    candidates: int = typer.Option(
        None,
        "--candidates",
        help="Retrieved templates to try with a short fit each; the best one's fit goes on in full (default 3; 1: the top result). Trials within 0.01 of each other get a note naming the other template.",
    ),
    device: str | None = ConfigDeviceOpt,
    renderer: str = RendererOpt,
    articulation: str = ArticulationOpt,
    focal: float = typer.Option(
        None,
        "--focal",
        help="Focal length in pixels of the input frames (default: from --lens, else the lens the video "
        "records, else a normal lens's: the frame's diagonal).",
    ),
    lens: float = typer.Option(
        None,
        "--lens",
        help="The lens as a 35 mm-equivalent focal length in mm (a phone's main camera: about 26); the focal "
        "follows from the frames' diagonal. Default: the lens the video records (see `zooctl video add "
        "--lens`), else a normal lens's (43 mm).",
    ),
    cameras: str = typer.Option(
        None,
        "--cameras",
        help="Known camera rotations: a .npz or .json with `rotations` (frames x 3 x 3, world-to-camera, "
        "OpenCV axes: x right, y down, z forward), or 'gt' for a `bench make` video's own cameras. The "
        "viewpoint search then finds the animal's one orientation in the world instead of tracking it.",
    ),
    config: Path = FitConfigOpt,
    seed: int = typer.Option(None, "--seed", help="Random seed."),
    texture: bool = typer.Option(
        None,
        "--texture/--no-texture",
        help="Bake the video's colours onto the character (a UV texture: the template's UVs, or an atlas "
        "made for it); --no-texture keeps the template's colours (with --resume too).",
    ),
    max_frames: int = typer.Option(None, "--max-frames", help="Fit only the first N frames."),
    resume: bool = typer.Option(
        False,
        "--resume",
        help="Continue the interrupted fit --name from its saved state; in a batch: skip the videos whose fit finished.",
    ),
    replace: bool = typer.Option(
        False,
        "--replace",
        help="Fit again under a name already in the store; the old fit stays whole until the new one "
        "finishes (without it, a name in use is refused).",
    ),
    json_out: bool = typer.Option(
        False, "--json", help="Print the fit record (a batch: its report) as JSON."
    ),
    batch: batch_opts.BatchOptions = batch_opts.BatchOpts,
) -> None:
    """Fit a rigged template to a video (CASA): camera search, global placement, articulation."""
    from rich.markup import escape

    from ..fit.config import load_config
    from ..fit.job import fit_job
    from ..video.ingest import parse_box

    cfg = load_config(config, preset_name)
    if iters is not None:
        cfg.stage2.iters = iters
    if candidates is not None:
        cfg.trials.candidates = candidates
    if device is not None:
        cfg.device = device
    if renderer is not None:
        cfg.stage1.renderer = cfg.stage2.renderer = renderer
    if articulation is not None:
        cfg.articulation = articulation
    if focal is not None:
        cfg.camera.focal = focal
    if lens is not None:
        cfg.camera.lens_35mm = lens
    if seed is not None:
        cfg.seed = seed
    if texture is not None:
        cfg.texture = texture
    if max_frames is not None:
        cfg.max_frames = max_frames
    if keep_shape:
        cfg.keep_shape()
    cfg.validate()
    if fit_many.wants_batch(videos, batch.executor):
        opts = dict(template=template, masks=masks, box=box, out=out, name=name, cameras=cameras)
        return fit_many.fit_many(
            videos, cfg, resume=resume, replace=replace, json_out=json_out, batch=batch, **opts
        )
    video = videos[0]
    with RichReporter() as rep:
        rec = fit_job(
            video,
            store_root(),
            cfg,
            name=name,
            template=template,
            masks=masks,
            out=out,
            reporter=rep,
            resume=resume,
            replace=replace,
            box=parse_box(box) if box else None,
            out_root=Path("fits"),
            cameras=cameras,
        )
    if json_out:
        print_json(rec)
        return
    if rec.get("retrieval"):
        console.print(
            "template candidates: "
            + ", ".join(
                f"{escape(c['name'])} ({c['score']:.3f}"
                + (f", trial IoU {c['trial_iou']:.3f}" if "trial_iou" in c else "")
                + (f" at iteration {c['pruned_at']}, stopped" if "pruned_at" in c else "")
                + ")"
                for c in rec["retrieval"][:5]
            ),
            highlight=False,
        )
    m = rec["metrics"]
    console.print(
        f"fitted [bold]{escape(rec['name'])}[/] with template {escape(rec['template'])}: mask IoU {m['mask_iou']:.3f} "
        f"(against {escape(masks_measured_against(rec.get('mask_source')))})"
        + (f", surface torn {100 * m['surface_tear']:.1f} %" if m.get("surface_tear") is not None else "")
        + f", {rec['timings']['total_wall']:.1f} s",
        highlight=False,
    )
    for k, p in rec["outputs"].items():
        console.print(f"  {k}: {escape(p)}", highlight=False)
    for n in rec.get("notes", []):
        err_console.print(f"[yellow]note:[/] {escape(n)}", highlight=False)


def masks_measured_against(source: str | None) -> str:
    """What a fit's mask IoU is measured against, for its one-line summary: a video's automatic
    masks are not ground truth, and the line must not read as if they were."""
    return {
        "given": "your masks",
        "masks": "your masks",
        "davis": "the folder's annotation masks",
        None: "the video's stored masks",
        "stored": "the video's stored masks",
    }.get(source, f"the video's automatic {source} masks, not ground truth")
