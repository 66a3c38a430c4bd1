"""`make demo`: seed the starter bank (and 30 random animals), film a starter animal walking (one of its own clips), fit it.

Leaves ``demo/`` with the fitted ``<name>.usd`` (with ``/World/Camera``), ``<name>.glb``,
``overlay.mp4`` (fit over the video, beside a turning view), ``loss.png`` and ``fit.json``, plus
the rendered input video in ``demo/video/``. Uses the store of this checkout (``./store``) unless
ZOOCTL_STORE says otherwise. ``python -m zooctl.demo [--animal quadruped] [--frames 36]``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

# The motion prior's budget as steps, not minutes: the same prior on an idle or a busy machine (a
# time budget trained a busy machine's prior into statues; BENCHMARKS.md, Motion prior).
DEMO_PRIOR_STEPS = 1600
# Random animals beside the starter set: of 0, 30, 60 and 100 the best on animals the bank does not
# hold, with two draws of 30 alike (BENCHMARKS.md, "More random animals").
DEMO_RANDOM_ANIMALS = 30
DEMO_RANDOM_SEED = 7


def main(argv: list[str] | None = None) -> int:
    from .benchdata.make import make_video
    from .cli._common import LineConsole, stage_progress
    from .errors import ZooctlError
    from .fit.config import preset
    from .fit.job import fit_job
    from .paths import default_store
    from .pipelines.bank_import import seed_starter
    from .store.bank import Bank

    ap = argparse.ArgumentParser(prog="python -m zooctl.demo", description=__doc__.splitlines()[0])
    ap.add_argument(
        "--animal", default="quadruped", help="starter animal to film and fit (default quadruped)"
    )
    ap.add_argument(
        "--clip",
        default="walk",
        help="the animal's own clip to film (default walk; 'random': random joint rotations)",
    )
    ap.add_argument("--frames", type=int, default=36)
    ap.add_argument("--size", type=int, default=240)
    ap.add_argument("--out", type=Path, default=Path("demo"))
    ap.add_argument(
        "--seed", type=int, default=int(time.time()) % 10000, help="motion seed (default: new each run)"
    )
    args = ap.parse_args(argv)
    con = LineConsole()
    try:
        store = default_store()
        bank = Bank.open(store)
        con.print(f"seeding the starter bank and {DEMO_RANDOM_ANIMALS} random animals (about a minute) ...")
        with stage_progress(True) as progress:
            added = seed_starter(bank, progress=lambda _, d, t: progress("starter animals", d, t))
            added += seed_starter(
                bank,
                seed=DEMO_RANDOM_SEED,
                random=DEMO_RANDOM_ANIMALS,
                progress=lambda _, d, t: progress("random animals", d, t),
            )
        con.print(f"starter bank at {store}/bank: {len(bank)} assets ({len(added)} added)")
        animal = bank.get(args.animal)
        own = args.clip != "random"
        video_dir = make_video(
            animal,
            args.out / "video",
            frames=args.frames,
            size=args.size,
            seed=args.seed,
            motion="clips" if own else "random",
            clip=args.clip if own else None,
        )
        con.print(
            f"filmed {args.animal} "
            + (f"in its {args.clip} clip" if own else "in random joint rotations")
            + f" from a moving camera (seed {args.seed}): {video_dir / 'video.mp4'}"
        )
        from .cli.fit import RichReporter

        cfg = preset("fast")
        with RichReporter() as rep:
            rec = fit_job(
                str(video_dir),
                store,
                cfg,
                name="demo",
                template=args.animal,
                out=args.out,
                reporter=rep,
                replace=True,
            )
    except ZooctlError as exc:
        con.print(f"[bold red]error:[/] {exc.message}" + (f"\n  hint: {exc.hint}" if exc.hint else ""))
        return exc.exit_code
    m = rec["metrics"]
    con.print(
        f"fitted in {rec['timings']['total_wall']:.0f} s: mask IoU {m['mask_iou']:.3f}, mIoU {m.get('miou') or 0:.3f}, joint {m.get('joint') or 0:.3f}"
    )
    for k, p in rec["outputs"].items():
        con.print(f"  {k}: {p}")
    con.print("open the .usd or .glb in Blender; overlay.mp4 shows the fit over the video")
    return _export_and_animate(con, args, rec)


def _zooctl(*args: str) -> None:
    """Run one real `zooctl` command, as a user would type it (the demo shows the user path)."""
    import subprocess

    cmd = [sys.executable, "-m", "zooctl", *args]
    print("$ zooctl " + " ".join(args), flush=True)
    if subprocess.run(cmd).returncode != 0:
        raise SystemExit(f"demo step failed: zooctl {' '.join(args)}")


def _export_and_animate(con, args, rec) -> int:
    """Export a starter animal, draw the bank's contact sheet, then put the fitted character in
    the bank, train a small motion prior on the starter clips and sample 5 motions for it."""
    out = args.out
    _zooctl("bank", "export", args.animal, "--all-clips", "-o", str(out / f"{args.animal}.usdz"))
    _zooctl("bank", "export", args.animal, "--all-clips", "-o", str(out / f"{args.animal}.glb"))
    _zooctl("bank", "render", "--sheet", "--tag", "procedural", "-o", str(out / "bank.png"))
    glb = next((v for v in rec["outputs"].values() if str(v).endswith(".glb")), None)
    if glb is None:
        con.print("[yellow]the fit wrote no .glb: skipping the motion demo[/]")
        _print_view_command(con)
        return 0
    _zooctl("bank", "add", glb, "--name", "demo-fit", "--replace", "--no-views", "--tag", "fitted")
    _zooctl(
        "motion", "train", "--assets", "quadruped,quadruped-longneck,quadruped-stout,biped,bird,spider,insect",
        "--name", "demo", "--max-steps", str(DEMO_PRIOR_STEPS), "--max-minutes", "4", "--replace",
    )  # fmt: skip
    _zooctl("animate", "demo-fit", "--sample", "5", "--prior", "demo", "--out", str(out / "animate"))
    con.print(f"done: everything is in {out}/ (fit, exports, bank.png, animate/)")
    _print_view_command(con)
    return 0


def _print_view_command(con) -> None:
    """The last line: the one command that opens the fit in the browser viewer (`zooctl view`,
    the zooctl-viewer plugin `make demo` installs)."""
    import importlib.util
    import os
    import shlex

    store = os.environ.get("ZOOCTL_STORE")
    cmd = "zooctl " + (f"--store {shlex.quote(store)} " if store else "") + "view demo"
    if importlib.util.find_spec("zooctl_viewer") is None:
        con.print("to look at the fit in 3D: pip install -e plugins/zooctl-viewer, then", highlight=False)
    else:
        con.print("turn the fitted animal around in your browser:", highlight=False)
    con.print(f"  $ {cmd}", highlight=False, markup=False)


if __name__ == "__main__":
    sys.exit(main())
