"""`zooctl embed train`: train the ``procnet`` retrieval embedder on procedural animals."""

from __future__ import annotations

import time
from pathlib import Path

import typer

from ._common import APP_OPTS, DeviceOpt, JsonOpt, console, print_json, store_root

RANDOMIZE_HELP = (
    "Domain randomisation of the training animals: any hue, flat facets half of the time, colour noise."
)
BANK_HELP = (
    "Then adapt the head to this store's bank: fine-tune on its assets' stored views (identity, plus "
    "body plan where a tag names one, e.g. --tag biped-dinosaur) mixed with the procedural ones."
)

app = typer.Typer(**APP_OPTS, help="Train retrieval embedders.", no_args_is_help=True)


@app.command("train")
def train(
    animals: int = typer.Option(
        320, "--animals", help="Random procedural animals to render (all body plans in turn)."
    ),
    views: int = typer.Option(12, "--views", help="Rendered views per animal."),
    steps: int = typer.Option(1500, "--steps", help="Training steps (batches of 32 animals x 4 views)."),
    minutes: float = typer.Option(None, "--minutes", help="Stop training after this many minutes."),
    seed: int = typer.Option(0, "--seed", help="Seed of the animals, their views and the training."),
    device: str = DeviceOpt,
    out: Path = typer.Option(None, "-o", "--out", help="Weights .npz (default: STORE/models/procnet.npz)."),
    cache: bool = typer.Option(True, "--cache/--no-cache", help="Reuse features cached in the store."),
    randomize: bool = typer.Option(False, "--randomize", help=RANDOMIZE_HELP),
    bank: bool = typer.Option(False, "--bank", help=BANK_HELP),
    bank_steps: int = typer.Option(300, "--bank-steps", help="Fine-tuning steps with --bank."),
    json_out: bool = JsonOpt,
) -> None:
    """Render random procedural animals, embed them with the frozen backbone and train the head."""
    from ..errors import UsageError

    if animals < 8 or views < 2 or steps < 1 or bank_steps < 1:
        raise UsageError(
            "need --animals >= 8, --views >= 2, --steps >= 1 and --bank-steps >= 1",
            hint="e.g. --animals 320 --views 12",
        )
    from rich.progress import Progress

    from ..retrieval.train_data import load_or_render
    from ..retrieval.train_embedder import TrainConfig, plot_losses, save_model, train_head

    root = store_root()
    out = out or Path(root) / "models" / "procnet.npz"  # = procnet.default_weights() without --store
    cfg = TrainConfig(steps=steps, seed=seed, minutes=minutes)
    bts = None
    if bank:  # before the slow part: a bank without views is refused at once
        from ..procedural.random import LABELS
        from ..retrieval.train_bank import bank_training_set
        from ..store.bank import Bank

        bts = bank_training_set(Bank.open(root), list(LABELS))
    t0 = time.perf_counter()
    with Progress(console=console, disable=json_out, transient=True) as bar:
        task = bar.add_task("render + embed animals", total=animals)
        ts = load_or_render(
            Path(root) / "cache" / "procnet" if cache else None,
            animals,
            views,
            seed,
            device=device,
            progress=lambda i, n: bar.update(task, completed=i),
            randomize=randomize,
        )
        t1 = time.perf_counter()
        task2 = bar.add_task("train head", total=steps)
        weights, losses = train_head(
            ts,
            cfg,
            device,
            progress=lambda i, n, loss: bar.update(
                task2, completed=i, description=f"train head (loss {loss:.2f})"
            ),
        )
        bank_info = None
        if bts is not None:
            task3 = bar.add_task("adapt to the bank", total=bank_steps)
            ft = TrainConfig(steps=bank_steps, lr=3e-4, seed=seed)
            weights, more = train_head(
                ts, ft, device, lambda i, n, loss: bar.update(task3, completed=i), bank=bts, init=weights
            )
            losses += more
            n_bank = len(set(bts.animal.tolist()))
            bank_info = {
                "assets": n_bank,
                "tagged": len(set(bts.animal[bts.label >= 0].tolist())),
                "steps": bank_steps,
            }
    t2 = time.perf_counter()
    meta = {
        "bank": bank_info,
        "randomize": randomize,
        "animals": animals,
        "views": views,
        "steps_run": len(losses),
        "final_loss": float(sum(losses[-50:]) / len(losses[-50:])),
    }
    path = save_model(out, weights, cfg, ts, meta)
    curve = plot_losses(
        losses, path.with_suffix(".loss.png"), f"procnet: {animals} animals x {views} views, seed {seed}"
    )
    res = {
        "weights": str(path),
        "loss_curve": str(curve),
        "render_embed_s": round(t1 - t0, 1),
        "train_s": round(t2 - t1, 1),
        **meta,
    }
    if json_out:
        print_json(res)
        return
    console.print(
        f"wrote {path} ({path.stat().st_size / 1e6:.1f} MB) and {curve}; render + embed {res['render_embed_s']} s, "
        f"train {res['train_s']} s, final loss {meta['final_loss']:.3f}. Use it: ZOOCTL_PROCNET_WEIGHTS={path}"
        + ("; then `zooctl bank reindex --embedder procnet`" if bank else ""),
        highlight=False,
        markup=False,
    )
