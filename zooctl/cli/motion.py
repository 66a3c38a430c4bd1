"""`zooctl motion ...`: train, list, show and remove motion priors."""

from __future__ import annotations

import time

import typer

from ._common import JsonOpt, console, err_console, print_json, print_table, store_root

app = typer.Typer(help="Train and manage generative motion priors (Ponymation).", no_args_is_help=True)


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
    name: str = typer.Option("ponymation", "--name", help="Name of the trained prior in the store."),
    epochs: int = typer.Option(50, "--epochs", min=1, help="Passes over all training windows."),
    max_minutes: float = typer.Option(
        20.0,
        "--max-minutes",
        min=0.01,
        help="Time budget: stop after this many minutes (at the end of a step); the learning-rate and "
        "KL schedules follow it. The default size does ~1 step per 10-30 s on a 2-core CPU: use "
        "--width 64 --layers 2 there, or a GPU.",
    ),
    device: str = typer.Option("cpu", "--device", help="cpu or cuda."),
    width: int = typer.Option(
        256, "--width", help="Transformer width (Ponymation: 256; 64-128 trains much faster on a CPU)."
    ),
    layers: int = typer.Option(4, "--layers", help="Layers in each of the four transformers."),
    latent: int = typer.Option(None, "--latent", help="Latent size (default: the width)."),
    length: int = typer.Option(10, "--length", help="Frames per training window (sequence length)."),
    batch_size: int = typer.Option(64, "--batch-size", help="Windows per step."),
    lr: float = typer.Option(3e-4, "--lr", help="Peak learning rate (AdamW, warm-up then cosine decay)."),
    kl_weight: float = typer.Option(
        1e-3, "--kl-weight", min=0.0, help="Weight of the KL term (Ponymation's best: 1e-3)."
    ),
    free_bits: float = typer.Option(
        0.5,
        "--free-bits",
        min=0.0,
        help="KL nats per latent dimension left unpenalised (prevents posterior collapse).",
    ),
    holdout: float = typer.Option(
        0.0,
        "--holdout",
        min=0.0,
        max=0.9,
        help="Fraction of each asset's clips held out for `zooctl bench motion`.",
    ),
    seed: int = typer.Option(0, "--seed", help="Random seed (initialisation, batches, hold-out split)."),
    threads: int = typer.Option(None, "--threads", help="CPU threads for torch (default: torch's choice)."),
    replace: bool = typer.Option(False, "--replace", help="Overwrite a prior of the same name."),
    json_out: bool = JsonOpt,
) -> None:
    """Train a motion prior on bank clips and store it (with its config and loss curve)."""
    from datetime import datetime, timezone

    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn

    from ..errors import UsageError
    from ..names import check_name
    from ..store.bank import Bank

    check_name(name, "motion prior name")
    store = _store()
    if store.exists(name) and not replace:
        raise store._exists(name)
    wanted = _split_names(assets)
    if all_assets == bool(wanted):
        raise UsageError(
            "name the assets to train on with --assets, or use --all (not both)",
            hint="zooctl motion train --all",
        )
    bank = Bank.open(store_root())
    names = bank.names() if all_assets else wanted
    loaded = []
    for n in names:
        a = bank.get(n)
        if a.clips:
            loaded.append(a)
        elif not all_assets:
            raise UsageError(
                f"asset {n!r} has no animation clips to learn from",
                hint="pick assets with clips (`zooctl bank list`)",
            )
    if not loaded:
        raise UsageError(
            "no bank asset with animation clips to train on",
            hint="add some: zooctl bank add FILE.glb, or zooctl bank seed",
        )
    if threads:
        import torch

        torch.set_num_threads(threads)

    from ..motion.evaluate import split_assets
    from ..motion.model import MotionConfig
    from ..motion.prior import PonymationPrior
    from ..motion.train import TrainOptions, loss_curve_png

    cfg = MotionConfig(
        width=width,
        layers=layers,
        latent=latent or width,
        length=length,
        kl_weight=kl_weight,
        free_bits=free_bits,
    )
    train_seqs, _, held = split_assets(loaded, holdout, seed)
    prior = PonymationPrior(cfg, device=device)
    data = prior.dataset(train_seqs)
    opts = TrainOptions(
        epochs=epochs, batch_size=batch_size, lr=lr, max_minutes=max_minutes, seed=seed, device=device
    )
    err_console.print(
        f"training {name!r}: {len(loaded)} assets, {len(data.sequence_names)} clips, {len(data)} windows of {length} frames, "
        f"width {width}, {layers} layers, {sum(p.numel() for p in prior.model.parameters()) / 1e6:.2f} M parameters, {device}",
        highlight=False,
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

        hist = prior.fit(data, opts, on_step)
    prior.training["assets"] = sorted(a.name for a in loaded)
    prior.training["holdout"] = held
    prior.training["seed"] = seed
    extra = {"created": datetime.now(timezone.utc).isoformat(timespec="seconds")}

    def write(tmp):
        prior.save(tmp, name, {**extra, "files": {"weights": "weights.pt", "loss_curve": "loss.png"}})
        (tmp / "loss.png").write_bytes(loss_curve_png(hist))

    t = time.perf_counter()
    path = store.add(name, write, replace=replace)
    cfg_json = store.config(name)
    if json_out:
        print_json({"path": str(path), "save_seconds": round(time.perf_counter() - t, 3), **cfg_json})
    else:
        fl = cfg_json["training"]["final_loss"]
        console.print(
            f"trained motion prior {name!r}: {hist.steps} steps in {hist.seconds:.0f} s"
            f"{' (stopped at --max-minutes)' if hist.stopped_early else ''}, final loss {fl['total']:.4f} "
            f"(rotation {fl['rotation']:.4f}, joints {fl['joints']:.5f}, KL {fl['kl']:.2f}); sampling temperature "
            f"{prior.sample_temperature:g} (calibrated to the clips' diversity); loss curve: {path / 'loss.png'}",
            highlight=False,
        )


@app.command("list")
def list_(json_out: bool = JsonOpt) -> None:
    """List the trained motion priors."""
    rows = _store().list()
    if json_out:
        print_json(rows)
        return
    if not rows:
        console.print("no motion priors (train one: zooctl motion train --all)", highlight=False)
        return
    table = []
    for c in rows:
        m, t = c.get("model", {}), c.get("training", {})
        table.append(
            [
                c["name"],
                c.get("plugin", "?"),
                f"{m.get('width', '?')}x{m.get('layers', '?')}",
                f"{c.get('parameters', 0) / 1e6:.2f}M",
                str(len(t.get("skeletons", []))),
                str(t.get("windows", "?")),
                str(t.get("steps", "?")),
                f"{t.get('sample_temperature', 1.0):g}",
                c.get("created", ""),
            ]
        )
    print_table(
        [
            ("name", "left"),
            ("plugin", "left"),
            ("width x layers", "left"),
            ("params", "right"),
            ("skeletons", "right"),
            ("windows", "right"),
            ("steps", "right"),
            ("temperature", "right"),
            ("created", "left"),
        ],
        table,
    )


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
