"""`zooctl bench motion`: held-out metrics of a trained motion prior against the baselines, and the
time to sample motions. Registered on the `zooctl bench` group by ``register(app)``."""

from __future__ import annotations

import typer

from ._common import (
    DeviceOpt,
    JsonOpt,
    PriorOpt,
    TemperatureOpt,
    console,
    print_json,
    print_table,
    store_root,
)


def bench_motion(
    prior_name: str = PriorOpt,
    samples: int = typer.Option(
        32, "--samples", min=2, help="Generated windows per skeleton (at least as many as held-out windows)."
    ),
    seed: int = typer.Option(0, "--seed", help="Sampling seed (the first, with --seeds)."),
    seeds: int = typer.Option(
        1, "--seeds", min=1, help="Sample with this many seeds and report their mean and standard deviation."
    ),
    temperature: float = TemperatureOpt,
    frames: int = typer.Option(60, "--frames", help="Frames per motion in the sampling timing."),
    repeats: int = typer.Option(3, "--repeats", help="Timed sampling runs (the median is reported)."),
    device: str = DeviceOpt,
    json_out: bool = JsonOpt,
) -> None:
    """Evaluate a prior on its held-out clips (train it with --holdout): reconstruction error,
    motion Chamfer distance, diversity, amplitude and speed ratios to the held-out clips (about 0
    for samples that stand still), gait periodicity, foot sliding and seam jumps; baselines in the
    same table."""
    import statistics
    import time

    from ..errors import UsageError
    from ..motion.evaluate import TABLE_COLUMNS, evaluate, format_table, split_assets
    from ..store.bank import Bank
    from ..store.motion_store import MotionStore

    store = MotionStore.open(store_root())
    name = prior_name or store.latest()
    cfg = store.config(name)
    training = cfg.get("training", {})
    holdout = training.get("holdout") or {}
    if not holdout:
        raise UsageError(
            f"motion prior {name!r} was trained on all its clips: nothing held out to evaluate on",
            hint="train with --holdout 0.2",
        )
    prior = store.load(name, device=device)
    bank = Bank.open(store_root())
    assets = [bank.get(a) for a in training.get("assets", sorted(holdout))]
    train, test, _ = split_assets(assets, holdout=holdout)
    result = evaluate(prior, train, test, samples=samples, seed=seed, temperature=temperature, seeds=seeds)
    big = max(assets, key=lambda a: a.num_joints)
    times = []
    for r in range(max(1, repeats)):
        t = time.perf_counter()
        prior.sample(big, n=5, frames=frames, seed=seed + r)
        times.append(time.perf_counter() - t)
    from ..render.benchmark import machine

    result.update(
        {
            "prior": name,
            "temperature": temperature if temperature is not None else prior.sample_temperature,
            "machine": machine(),
            "sampling": {
                "asset": big.name,
                "joints": big.num_joints,
                "samples": 5,
                "frames": frames,
                "median_seconds": round(statistics.median(times), 3),
                "device": device,
            },
        }
    )
    if json_out:
        print_json(result)
        return
    print_table(
        TABLE_COLUMNS,
        format_table(result),
        title=f"motion prior {name!r}: {len(result['skeletons'])} skeletons, "
        f"{result['held_out_windows']} held-out windows",
    )
    console.print(f"units: {result['units']}", highlight=False, style="dim")
    s = result["sampling"]
    console.print(
        f"sampling 5 x {frames} frames for {s['asset']} ({s['joints']} joints): {s['median_seconds']:.3f} s median ({device})",
        highlight=False,
    )


def register(app: typer.Typer) -> None:
    app.command("motion")(bench_motion)
