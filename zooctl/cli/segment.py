"""`zooctl segment train`: train the ``animalnet`` segmenter's head on synthetic composites."""

from __future__ import annotations

from pathlib import Path

import typer

from ._common import APP_OPTS, DeviceOpt, JsonOpt, console, print_json, store_root

app = typer.Typer(**APP_OPTS, help="Train the learned video segmenter.", no_args_is_help=True)


@app.command("train")
def train(
    samples: int = typer.Option(2000, "--samples", help="Synthetic composites to render (two frames each)."),
    steps: int = typer.Option(1500, "--steps", help="Training steps (batches of 16 composites)."),
    procedural: int = typer.Option(
        40, "--procedural", help="Random procedural animals added to the bank's assets (0: the bank's only)."
    ),
    bank: bool = typer.Option(True, "--bank/--no-bank", help="Train on this store's bank assets too."),
    seed: int = typer.Option(0, "--seed", help="Seed of the animals, the composites and the training."),
    device: str = DeviceOpt,
    out: Path = typer.Option(None, "-o", "--out", help="Weights .npz (default: STORE/models/animalnet.npz)."),
    json_out: bool = JsonOpt,
) -> None:
    """Render animals over procedural scenes and train the head `video add --segmenter animalnet` uses."""
    from ..errors import UsageError

    if samples < 10 or steps < 1 or procedural < 0:
        raise UsageError(
            "need --samples >= 10, --steps >= 1 and --procedural >= 0", hint="e.g. --samples 2000"
        )
    from rich.progress import Progress

    from ..pipelines.segment_train import SegmentTrainConfig
    from ..pipelines.segment_train import train as train_job
    from ..procedural.random import random_assets
    from ..store.bank import Bank

    root = store_root()
    out = out or Path(root) / "models" / "animalnet.npz"  # = animalnet.default_weights() without --store
    assets, names = [], []
    if bank:
        b = Bank.open(root)
        names = b.names()
        assets = [b.get(n) for n in names]
    assets += random_assets(procedural, seed, any_hue=True)
    if not assets:
        raise UsageError(
            "nothing to train on: the bank is empty and --procedural is 0",
            hint="add assets or use --procedural 40",
        )
    sources = {
        "bank_assets": names,
        "procedural_animals": procedural,
        "scenes": "procedural (zooctl.benchdata.composites); no video frames",
        "licence": "the bank assets' own licences; procedural animals and scenes are zooctl's own",
    }
    cfg = SegmentTrainConfig(samples=samples, steps=steps, seed=seed)
    with Progress(console=console, disable=json_out, transient=True) as bar:
        tasks: dict[str, int] = {}

        def progress(stage: str, i: int, n: int) -> None:
            if stage not in tasks:
                tasks[stage] = bar.add_task(stage, total=n)
            bar.update(tasks[stage], completed=i)

        info = train_job(assets, out, cfg, sources, progress, device)
    res = {"weights": str(out), **info}
    if json_out:
        print_json(res)
        return
    r = info["report"]
    console.print(
        f"wrote {out}: {len(assets)} animals, {samples} composites in {info['seconds']['composites']} s, "
        f"trained in {info['seconds']['training']} s; held-out cell IoU {r['held_out_cell_iou']:.3f} "
        f"(synthetic). Use it: zooctl video add VIDEO --segmenter animalnet",
        highlight=False,
        markup=False,
    )
