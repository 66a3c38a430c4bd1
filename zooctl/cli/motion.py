"""`zooctl motion ...`: train, list, show and remove motion priors."""

from __future__ import annotations

import time

import typer

from ..motion.temperature import default_temperature, draws_diversely
from ._common import APP_OPTS, DeviceOpt, JsonOpt, console, err_console, print_json, print_listing, store_root

app = typer.Typer(
    **APP_OPTS, help="Train and manage generative motion priors (Ponymation).", no_args_is_help=True
)


def _store():
    from ..store.motion_store import MotionStore

    return MotionStore.open(store_root())


def _split_names(values: list[str] | None) -> list[str]:
    return [n.strip() for v in values or [] for n in v.split(",") if n.strip()]


@app.command("train")
def train(
    assets: list[str] = typer.Option(
        None, "--assets", "-a", help="Bank assets whose clips to train on (repeatable or comma-separated)."
    ),
    all_assets: bool = typer.Option(False, "--all", help="Train on every bank asset with clips."),
    fits: list[str] = typer.Option(
        None,
        "--fits",
        help="Fitted videos whose motion to train on (repeatable or comma-separated; with or without clips).",
    ),
    all_fits: bool = typer.Option(False, "--all-fits", help="Train on every finished fit."),
    kind: str = typer.Option(
        None,
        "--kind",
        help="Motion prior to train: any registered one (`zooctl plugins`). Default: ponymation.",
    ),
    arch: str = typer.Option(
        None,
        "--arch",
        help="Ponymation's model: 'ponymation' (per-frame spatial + temporal transformers, the paper's; "
        "default on CUDA) or 'trajectory' (one token per bone holding its window; several times more "
        "steps per minute; default on a CPU).",
    ),
    name: str = typer.Option("ponymation", "--name", help="Name of the trained prior in the store."),
    epochs: int = typer.Option(None, "--epochs", min=1, help="Passes over all training windows at most."),
    max_minutes: float = typer.Option(
        None,
        "--max-minutes",
        min=0.01,
        help="Time budget: stop after this many minutes (at the end of a step); the learning-rate and "
        "KL schedules follow it. Default: 20.",
    ),
    max_steps: int = typer.Option(
        None,
        "--max-steps",
        min=1,
        help="Step budget: stop after this many steps, or at --max-minutes if that comes first; the "
        "schedules follow whichever ends first (a fixed amount of work, whatever the machine's load).",
    ),
    device: str = DeviceOpt,
    width: int = typer.Option(
        None, "--width", help="Transformer width. Default by device: 256 on CUDA (Ponymation's), 64 on a CPU."
    ),
    layers: int = typer.Option(
        None, "--layers", help="Layers in each of the four transformers. Default: 4 on CUDA, 2 on a CPU."
    ),
    latent: int = typer.Option(None, "--latent", help="Latent size (default: the width)."),
    length: int = typer.Option(
        None, "--length", help="Frames per training window (default: the prior's; ponymation 10, pca 30)."
    ),
    batch_size: int = typer.Option(None, "--batch-size", help="Windows per step (default: 64 CUDA, 32 CPU)."),
    lr: float = typer.Option(
        None, "--lr", help="Peak learning rate (AdamW, warm-up then cosine; default 3e-4 CUDA, 1e-3 CPU)."
    ),
    kl_weight: float = typer.Option(
        None, "--kl-weight", min=0.0, help="Weight of the KL term (default: Ponymation's best, 1e-3)."
    ),
    free_bits: float = typer.Option(
        None,
        "--free-bits",
        min=0.0,
        help="KL nats per latent dimension left unpenalised (prevents posterior collapse; default 0.5).",
    ),
    holdout: float = typer.Option(
        None,
        "--holdout",
        min=0.0,
        max=0.9,
        help="Fraction of each asset's clips held out for `zooctl bench motion` (default 0).",
    ),
    seed: int = typer.Option(None, "--seed", help="Random seed (initialisation, batches, hold-out split)."),
    threads: int = typer.Option(None, "--threads", help="CPU threads for torch (default: torch's choice)."),
    replace: bool = typer.Option(False, "--replace", help="Overwrite a prior of the same name."),
    json_out: bool = JsonOpt,
) -> None:
    """Train a motion prior on bank clips and/or fitted videos and store it (with its config and
    loss curve). The model size follows the device unless given (said in the output)."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    from ..pipelines.motion_train import MotionTrainOptions, gather_sequences, train_motion_prior

    given = {
        "kind": kind,
        "arch": arch,
        "epochs": epochs,
        "max_minutes": max_minutes,
        "max_steps": max_steps,
        "device": device,
        "width": width,
        "layers": layers,
        "latent": latent,
        "length": length,
        "batch_size": batch_size,
        "lr": lr,
        "kl_weight": kl_weight,
        "free_bits": free_bits,
        "holdout": holdout,
        "seed": seed,
        "threads": threads,
    }
    opts = MotionTrainOptions(**{k: v for k, v in given.items() if v is not None})
    loaded, fit_seqs = gather_sequences(
        store_root(), _split_names(assets), all_assets, _split_names(fits), all_fits
    )
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total} steps"),
        TextColumn("loss {task.fields[loss]}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=err_console,
        transient=False,
        disable=json_out,
    ) as progress:
        task = progress.add_task("training", total=None, loss="-")

        def on_step(step: int, total: int, losses: dict[str, float]) -> None:
            progress.update(task, completed=step, total=total, loss=f"{losses['total']:.4f}")

        def log(line: str) -> None:
            if not json_out:
                err_console.print(line, highlight=False, soft_wrap=True)

        t = time.perf_counter()
        cfg = train_motion_prior(store_root(), name, opts, loaded, fit_seqs, replace, on_step, log)
    if json_out:
        print_json({"seconds": round(time.perf_counter() - t, 3), **cfg})
        return
    tr = cfg.get("training", {})
    fl = tr.get("final_loss") or {}
    loss = (
        f", final loss {fl['total']:.4f} (rotation {fl['rotation']:.4f}, joints {fl['joints']:.5f}, "
        f"velocity {fl.get('velocity') or 0:.3f}, KL {fl['kl']:.2f})"
        if fl.get("total") is not None
        else ""
    )
    steps = f": {tr['steps']} steps in {tr.get('seconds', 0):.0f} s" if "steps" in tr else ""
    at_steps = tr.get("max_steps") is not None and tr.get("steps") == tr.get("max_steps")
    early = (
        f" (stopped at {'--max-steps' if at_steps else '--max-minutes'})" if tr.get("stopped_early") else ""
    )
    model = cfg.get("model", {})
    how = "each window's posterior" if draws_diversely(model) else "calibrated to the clips' diversity"
    temp = f"; sampling temperature {default_temperature(model, tr):g} ({how})"
    console.print(
        f"trained motion prior {cfg['name']!r} ({cfg.get('plugin')}, {tr.get('size', '')}){steps}{early}"
        f"{loss}{temp}; in {cfg['path']}",
        highlight=False,
    )


@app.command("list")
def list_(json_out: bool = JsonOpt) -> None:
    """List the trained motion priors."""

    def cells(c: dict) -> list[str]:
        m, t = c.get("model", {}), c.get("training", {})
        return [
            c["name"],
            c.get("plugin", "?"),
            f"{m.get('width', '?')}x{m.get('layers', '?')}",
            f"{c.get('parameters', 0) / 1e6:.2f}M",
            str(len(t.get("skeletons", []))),
            str(t.get("windows", "?")),
            str(t.get("steps", "?")),
            f"{default_temperature(m, t):g}",
            c.get("created", ""),
        ]

    cols = [
        ("name", "left"),
        ("plugin", "left"),
        ("width x layers", "left"),
        ("params", "right"),
        ("skeletons", "right"),
        ("windows", "right"),
        ("steps", "right"),
        ("temperature", "right"),
        ("created", "left"),
    ]
    empty = "no motion priors (train one: zooctl motion train --all)"
    print_listing(_store().list(), json_out, cols, cells, empty=empty)


@app.command("show")
def show(name: str = typer.Argument(..., help="Prior name."), json_out: bool = JsonOpt) -> None:
    """Show a prior's configuration and what it was trained on."""
    store = _store()
    c = store.config(name)
    if json_out:
        print_json({"path": str(store.path(name)), **c})
        return
    m, t = c.get("model", {}), c.get("training", {})
    console.print(
        f"[bold]{c['name']}[/] ({c.get('plugin')}, {c.get('parameters', 0) / 1e6:.2f} M parameters) at {store.path(name)}",
        highlight=False,
    )
    console.print("model: " + ", ".join(f"{k}={v}" for k, v in m.items()), highlight=False)
    fl = t.get("final_loss") or {}
    console.print(
        f"trained: {t.get('steps')} steps, {t.get('epochs')} epochs, {t.get('seconds')} s on {t.get('device')}; "
        f"{len(t.get('sequences', []))} clips of {len(t.get('skeletons', []))} skeletons, {t.get('windows')} windows; "
        f"final loss {fl.get('total')}",
        highlight=False,
    )
    held = t.get("holdout") or {}
    console.print(
        f"held out: {sum(len(v) for v in held.values())} clips of {len(held)} assets", highlight=False
    )


@app.command("rm")
def rm(names: list[str] = typer.Argument(..., help="Priors to remove.")) -> None:
    """Remove motion priors from the store."""
    store = _store()
    for n in names:
        store.remove(n)
        console.print(f"removed motion prior {n!r}", highlight=False)
