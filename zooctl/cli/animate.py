"""`zooctl animate TARGET --sample N` / `zooctl animate --image photo.jpg`: sample motions for a
character and export them (logic in `zooctl.pipelines.animate`)."""

from __future__ import annotations

from pathlib import Path

import typer

from ._common import (
    DeviceOpt,
    JsonOpt,
    PriorOpt,
    TemperatureOpt,
    console,
    err_console,
    print_json,
    store_root,
)


def animate(
    target: str = typer.Argument(
        None, help="Bank asset or fit to animate (`fit:NAME` when a bank asset has the same name)."
    ),
    image: Path = typer.Option(
        None, "--image", help="Animate a photo instead: fit it first (single-image CASA fit), then sample."
    ),
    masks: str = typer.Option(
        None, "--masks", help="With --image: folder holding the photo's mask (an image, white = animal)."
    ),
    template: str = typer.Option(
        None, "--template", help="With --image: bank asset to fit (default: template retrieval)."
    ),
    fit_config: Path = typer.Option(
        None, "--fit-config", help="With --image: JSON fit config applied on top of the fast preset."
    ),
    sample: int = typer.Option(5, "--sample", "-n", min=1, max=64, help="How many motions to sample."),
    frames: int = typer.Option(
        60,
        "--frames",
        min=2,
        max=10000,
        help="Frames per motion (longer than the prior's window: chained segments).",
    ),
    seed: int = typer.Option(0, "--seed", help="Random seed."),
    temperature: float = TemperatureOpt,
    prior_name: str = PriorOpt,
    out: Path = typer.Option(None, "--out", help="Output folder (default: ./animate-TARGET)."),
    formats: str = typer.Option(
        "usd,glb", "--formats", help="Comma-separated export formats (any registered exporter)."
    ),
    preview: bool = typer.Option(
        True, "--preview/--no-preview", help="Render a preview video and a contact sheet."
    ),
    size: int = typer.Option(128, "--size", help="Preview image size in pixels (per tile)."),
    preview_fps: float = typer.Option(
        5.0,
        "--preview-fps",
        min=0.0,
        help="Frames per second the preview renders and plays (same duration; 0: every frame).",
    ),
    device: str = DeviceOpt,
    json_out: bool = JsonOpt,
) -> None:
    """Sample motions for a bank asset, a fit or a photo: USD + GLB each, a preview, a contact sheet."""
    from ..errors import UsageError
    from ..pipelines.animate import AnimateOptions, fit_image, resolve_target, sample_and_export

    if (target is None) == (image is None):
        raise UsageError(
            "give either TARGET (a bank asset or a fit) or --image PHOTO",
            hint="e.g. `zooctl animate quadruped --sample 5` or `zooctl animate --image cat.jpg --masks cat_mask/`",
        )
    if image is None and (masks is not None or template is not None or fit_config is not None):
        raise UsageError("--masks, --template and --fit-config only apply with --image")
    opts = AnimateOptions(
        sample=sample,
        frames=frames,
        seed=seed,
        temperature=temperature,
        prior=prior_name,
        formats=tuple(f.strip().lower() for f in formats.split(",") if f.strip()),
        preview=preview,
        size=size,
        preview_fps=preview_fps,
        device=device,
    )
    if image is not None:
        from .fit import RichReporter

        with RichReporter() as rep:
            asset, label = fit_image(
                image, store_root(), masks, template, fit_config, device=device, reporter=rep
            )
        err_console.print(f"fitted the photo as {label!r} (`zooctl fits show {label}`)", highlight=False)
    else:
        asset, _ = resolve_target(store_root(), target)
        label = target.removeprefix("fit:")
    manifest = sample_and_export(asset, label, out or Path(f"animate-{label}"), opts, store_root())
    if json_out:
        print_json(manifest)
        return
    t = manifest["seconds"]["sample_and_export"]
    console.print(
        f"{sample} motions of {frames} frames for {label!r} from prior {manifest['prior']!r} in "
        f"{out or Path(f'animate-{label}')}/ (sampling + export {t:.2f} s)",
        highlight=False,
    )
    for kind, paths in manifest["files"].items():
        console.print(f"  {kind}: " + ", ".join(Path(p).name for p in paths), highlight=False)
    if not preview:
        err_console.print("preview skipped (--no-preview)", style="dim")
