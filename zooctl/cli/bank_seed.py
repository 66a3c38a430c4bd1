"""`zooctl bank seed`: the procedural starter animals."""

from __future__ import annotations

import typer

from ._common import JsonOpt, ViewsOpt, console, open_bank, print_json, stage_progress


def seed(
    seed_value: int = typer.Option(
        0, "--seed", help="Random seed for proportions and colours (same seed, same animals)."
    ),
    plan: list[str] = typer.Option(
        None,
        "--plan",
        help="Only this body plan (repeatable): quadruped, biped (upright, with arms), dinosaur (level biped "
        "with a long tail), bird, fish, snake, insect, spider, crab; with --random the labels quadruped, "
        "'quadruped dinosaur', 'biped dinosaur', humanoid, bird, fish, snake, insect, spider, crab.",
    ),
    random: int = typer.Option(
        0,
        "--random",
        help="Add this many random animals (every plan in turn, random proportions within its range) "
        "instead of the starter set.",
    ),
    no_variants: bool = typer.Option(
        False, "--no-variants", help="One animal per plan, without the proportion variants."
    ),
    replace: bool = typer.Option(False, "--replace", help="Overwrite starter animals already in the bank."),
    views: bool | None = ViewsOpt,
    json_out: bool = JsonOpt,
) -> None:
    """Add the procedural starter animals, or --random N random ones (rigged, skinned, animated; generated)."""
    if random < 0:
        from ..errors import UsageError

        raise UsageError(f"--random {random} must be 0 or more")
    from ..pipelines.bank_import import seed_starter

    bank = open_bank()
    with stage_progress(not json_out) as progress:
        added = seed_starter(
            bank,
            seed=seed_value,
            plans=list(plan) if plan else None,
            variants=not no_variants,
            replace=replace,
            views=views,
            progress=progress,
            random=random,
        )
    if json_out:
        print_json({"added": added, "bank_size": len(bank.names())})
    else:
        console.print(
            f"added {len(added)} {'random' if random else 'starter'} animals"
            + (f": {', '.join(added)}" if added else " (all present; --replace to rebuild)"),
            highlight=False,
            markup=False,
        )


def register(app: typer.Typer) -> None:
    app.command("seed")(seed)
