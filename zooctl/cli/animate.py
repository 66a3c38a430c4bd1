"""`zooctl animate TARGET --sample N`: sample motions for a bank asset and export them."""

from __future__ import annotations

from pathlib import Path

import typer

from ._common import JsonOpt, console, err_console, print_json, store_root


def animate(
    target: str = typer.Argument(..., help="Bank asset to animate."),
    sample: int = typer.Option(5, "--sample", "-n", min=1, max=64, help="How many motions to sample."),
    frames: int = typer.Option(
        60,
        "--frames",
        min=2,
        max=10000,
        help="Frames per motion (longer than the prior's window: chained segments).",
    ),
    seed: int = typer.Option(0, "--seed", help="Random seed."),
    temperature: float = typer.Option(
        1.0,
        "--temperature",
        min=0.0,
        help="Scale of the latent's standard deviation: lower is closer to typical motion, higher more varied.",
    ),
    prior_name: str = typer.Option(
        None, "--prior", help="Motion prior (default: the most recently trained)."
    ),
    out: Path = typer.Option(None, "--out", help="Output folder (default: ./animate-TARGET)."),
    formats: str = typer.Option(
        "usd,glb", "--formats", help="Comma-separated export formats (any registered exporter)."
    ),
    preview: bool = typer.Option(
        True, "--preview/--no-preview", help="Render a preview video and a contact sheet."
    ),
    size: int = typer.Option(192, "--size", help="Preview image size in pixels."),
    device: str = typer.Option("cpu", "--device", help="cpu or cuda."),
    json_out: bool = JsonOpt,
) -> None:
    """Sample motions from a trained prior for an asset; write USD + GLB per motion, a preview
    video and a contact sheet."""
    import dataclasses
    import json
    import time

    from ..errors import MissingDependencyError
    from ..motion.prior import motion_clip
    from ..plugins import get_registry
    from ..store.bank import Bank
    from ..store.fs import write_bytes_atomic
    from ..store.motion_store import MotionStore

    t0 = time.perf_counter()
    asset = Bank.open(store_root()).get(target)
    store = MotionStore.open(store_root())
    prior_name = prior_name or store.latest()
    prior = store.load(prior_name, device=device)
    fmts = [f.strip().lower() for f in formats.split(",") if f.strip()]
    registry = get_registry()
    exporters = {}
    for f in fmts:
        spec = registry.exporter_for(f)
        if spec is None:
            raise MissingDependencyError(
                f"no exporter for format {f!r}", hint="see `zooctl plugins` for the formats available"
            )
        exporters[f] = spec
    options = {"temperature": temperature} if temperature != 1.0 else {}  # not every prior plugin has it
    rots = prior.sample(asset, n=sample, frames=frames, seed=seed, **options)  # (n, frames, J, 4)
    t_sample = time.perf_counter() - t0
    fps = float(getattr(getattr(prior, "cfg", None), "fps", 30.0))
    names = [f"sample{i:02d}" for i in range(sample)]
    animated = dataclasses.replace(
        asset, clips={n: motion_clip(asset, r, fps, n) for n, r in zip(names, rots, strict=True)}
    )
    out = out or Path(f"animate-{target}")
    out.mkdir(parents=True, exist_ok=True)
    files: dict[str, list[str]] = {f: [] for f in fmts}
    for n in names:
        for f, spec in exporters.items():
            path = out / f"{target}_{n}.{f}"
            spec.save(animated, path, clips=[n])
            files[f].append(str(path))
    t_export = time.perf_counter() - t0
    if preview:
        files.update(_preview(animated, names, out, target, size, fps, device))
    manifest = {
        "target": target,
        "prior": prior_name,
        "samples": sample,
        "frames": frames,
        "fps": fps,
        "seed": seed,
        "temperature": temperature,
        "files": files,
        "seconds": {
            "sample": round(t_sample, 3),
            "sample_and_export": round(t_export, 3),
            "total": round(time.perf_counter() - t0, 3),
        },
    }
    write_bytes_atomic(out / "animate.json", (json.dumps(manifest, indent=1) + "\n").encode())
    if json_out:
        print_json(manifest)
    else:
        console.print(
            f"{sample} motions of {frames} frames for {target!r} from prior {prior_name!r} in {out}/ "
            f"(sampling + export {t_export:.2f} s)",
            highlight=False,
        )
        for kind, paths in files.items():
            console.print(f"  {kind}: " + ", ".join(Path(p).name for p in paths), highlight=False)
    if not preview:
        err_console.print("preview skipped (--no-preview)", style="dim")


def _preview(
    asset, clips: list[str], out: Path, target: str, size: int, fps: float, device: str
) -> dict[str, list[str]]:
    """A video with every sample side by side, and a contact sheet (one row of frames per sample)."""
    import numpy as np

    from ..io.video import write_mp4
    from ..render.preview import contact_sheet, render_asset, save_png

    videos = [
        render_asset(asset, c, size=size, supersample=1, device=device) for c in clips
    ]  # (T, H, W, 3) each
    cols = min(len(clips), 5)
    grid = [contact_sheet([v[t] for v in videos], labels=clips, columns=cols) for t in range(len(videos[0]))]
    video = write_mp4(out / f"{target}_samples.mp4", np.stack(grid), fps=fps)
    T = len(videos[0])
    picks = np.linspace(0, T - 1, min(T, 6)).round().astype(int)
    tiles = [v[t] for v in videos for t in picks]
    labels = [f"{c} f{t}" for c in clips for t in picks]
    sheet = save_png(
        out / f"{target}_contact_sheet.png", contact_sheet(tiles, labels=labels, columns=len(picks))
    )
    return {"preview": [str(video)], "contact_sheet": [str(sheet)]}
