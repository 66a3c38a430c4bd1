"""Motion-prior benchmark (issue 8): train on the clips of the 28 shared assets with 20 % of each
asset's clips held out, then report held-out metrics against the baselines, and the time to sample
5 motions of 60 frames for the largest skeleton with USD + GLB export.

    .venv/bin/python bench/motion.py [--width 256 --layers 4] [--minutes 20] [--steps N] [--epochs 50]
                                     [--device cpu] [--threads 2] [--out bench/out/motion.json]
                                     [--save DIR | --load DIR] [--free-bits 0.5] [--lr 3e-4]
                                     [--rot-loss relative|mse] [--no-timing]

``--steps N`` fixes the amount of training (the schedules follow the larger of steps / N and time /
``--minutes``), so runs on a shared machine can be compared; the output also gives the
reconstruction amplitude ratio of training and held-out windows (posterior mean decoded / data).

Sampling is timed twice: with the benchmarked prior and with a default-size (256 x 4) model, whose
speed does not depend on its weights. ``--load DIR`` evaluates a prior saved with ``--save DIR``.

Everything runs through the library (the same code as `zooctl motion train` / `zooctl bench
motion` / `zooctl animate`), with the assets imported straight from the shared folder.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import torch
from _util import SHARED, machine

from zooctl.io.gltf_import import load_gltf
from zooctl.motion.calibrate import calibrate_temperature
from zooctl.motion.evaluate import TABLE_COLUMNS, evaluate, format_table, pca_curve, split_assets
from zooctl.motion.mirror import mirror_sequence
from zooctl.motion.model import MotionConfig
from zooctl.motion.prior import PonymationPrior, motion_clip
from zooctl.motion.temperature import draws_diversely
from zooctl.motion.train import TrainOptions, loss_curve_png
from zooctl.names import sanitize_name
from zooctl.pipelines.motion_train import device_defaults
from zooctl.plugins import get_registry


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--width", type=int, default=None, help="default: by device (zooctl motion train's)")
    ap.add_argument("--layers", type=int, default=None)
    ap.add_argument("--epochs", type=int, default=1000)
    ap.add_argument("--minutes", type=float, default=20.0, help="training time budget")
    ap.add_argument(
        "--steps",
        type=int,
        default=None,
        help="train at most this many steps (a fixed amount of work whatever the load; --minutes still stops it)",
    )
    ap.add_argument("--length", type=int, default=MotionConfig.length, help="frames per window")
    ap.add_argument("--rot-loss", default=MotionConfig.rot_loss, choices=("mse", "relative"))
    ap.add_argument("--rot-weight", type=float, default=MotionConfig.rot_weight)
    ap.add_argument("--joint-weight", type=float, default=MotionConfig.joint_weight)
    ap.add_argument("--latent", type=int, default=None, help="latent size (default: the width)")
    ap.add_argument("--free-bits", type=float, default=MotionConfig.free_bits)
    ap.add_argument("--kl-weight", type=float, default=MotionConfig.kl_weight)
    ap.add_argument("--recon-warmup", type=float, default=TrainOptions.recon_warmup)
    ap.add_argument("--kl-anneal", type=float, default=TrainOptions.kl_anneal)
    ap.add_argument("--velocity-weight", type=float, default=MotionConfig.velocity_weight)
    ap.add_argument("--rot-velocity-weight", type=float, default=MotionConfig.rot_velocity_weight)
    ap.add_argument("--z-tokens", type=int, default=MotionConfig.z_tokens, help="trajectory model's z tokens")
    ap.add_argument("--sampler", default=MotionConfig.sampler, choices=("mixture", "posterior", "normal"))
    ap.add_argument(
        "--donors", type=int, default=None, help="mixture sampling's donor skeletons (default: the model's)"
    )
    ap.add_argument(
        "--donor-share", type=float, default=None, help="share of windows from donors (default: the model's)"
    )
    ap.add_argument(
        "--independent",
        action="store_true",
        help="mixture sampling draws each sample's window independently (default: spread, `diverse`)",
    )
    ap.add_argument(
        "--recalibrate",
        action="store_true",
        help="with --load: calibrate the temperature again (sampling settings as set; a prior that "
        "draws diversely samples at 1 whatever it is, so this needs --independent there)",
    )
    ap.add_argument("--mirror", action="store_true", help="train on the clips' left-right mirrors too")
    ap.add_argument(
        "--mirror-baselines",
        action="store_true",
        help="fit the PCA and nearest-clip baselines on the training clips and their mirrors too",
    )
    ap.add_argument("--arch", default=None, choices=("ponymation", "trajectory"), help="default: by device")
    ap.add_argument("--lr", type=float, default=None)
    ap.add_argument("--batch-size", type=int, default=None)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--samples", type=int, default=32)
    ap.add_argument(
        "--seeds",
        type=int,
        default=5,
        help="sampling seeds 0..N-1; the table is their mean (one seed is noisy)",
    )
    ap.add_argument(
        "--temperature",
        type=float,
        default=None,
        help="scale of the prior's sigma (default: its calibrated one)",
    )
    ap.add_argument(
        "--pca-spread",
        type=float,
        action="append",
        default=None,
        help="also score the PCA baseline with its spread scaled by this (repeatable): MCD at equal diversity",
    )
    ap.add_argument("--out", type=Path, default=Path("bench/out/motion.json"))
    ap.add_argument("--save", type=Path, default=None, help="also save the trained prior in this folder")
    ap.add_argument("--load", type=Path, default=None, help="evaluate a prior saved with --save, no training")
    ap.add_argument("--no-timing", action="store_true", help="skip timing the sampling")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    for k, v in device_defaults(args.device).items():
        if k in ("arch", "width", "layers", "batch_size", "lr") and getattr(args, k) is None:
            setattr(args, k, v)
    files = sorted((SHARED / "assets" / "quaternius").glob("*/*.glb"))
    if not files:
        sys.exit(f"bench/motion.py needs the shared assets at {SHARED / 'assets'}")
    assets = [load_gltf(f, sanitize_name(f.stem)) for f in files]
    train, test, held = split_assets(assets, 0.2, seed=0)
    cfg = MotionConfig(
        width=args.width,
        layers=args.layers,
        latent=args.latent or args.width,
        length=args.length,
        rot_loss=args.rot_loss,
        rot_weight=args.rot_weight,
        joint_weight=args.joint_weight,
        free_bits=args.free_bits,
        kl_weight=args.kl_weight,
        velocity_weight=args.velocity_weight,
        rot_velocity_weight=args.rot_velocity_weight,
        z_tokens=args.z_tokens,
        sampler=args.sampler,
        arch=args.arch,
        mirror=args.mirror,
    )
    prior = PonymationPrior(cfg, device=args.device)
    data = prior.dataset(train)
    print(
        f"{len(assets)} assets, {len(train)} training clips ({len(data)} windows), {len(test)} held out; "
        f"model {args.arch} {args.width}x{args.layers}, {sum(p.numel() for p in prior.model.parameters()) / 1e6:.2f} M parameters",
        flush=True,
    )
    if args.load:
        prior = PonymationPrior.load(args.load, device=args.device)
        cfg = prior.cfg
    for field in ("donors", "donor_share"):  # sampling only: may change a loaded prior's
        if getattr(args, field) is not None:
            setattr(prior.cfg, field, getattr(args, field))
    if args.independent:
        prior.cfg.diverse = False
    if args.load and args.recalibrate:
        if draws_diversely(prior.cfg.to_json()):
            raise SystemExit(
                "--recalibrate: this prior draws diversely and samples at temperature 1 whatever the "
                "calibration says; add --independent to calibrate independent draws"
            )
        cal = calibrate_temperature(prior, prior.dataset(train))
        prior.training["sample_temperature"] = cal["temperature"]
        print(f"calibrated again: temperature {cal['temperature']} {cal['diversity']}", flush=True)
    if not args.load:
        train_prior(prior, data, args)
    if args.save:
        prior.save(args.save, "bench-motion")
    prior.device = torch.device("cpu")
    prior.model.to("cpu")
    base = train
    if args.mirror_baselines:
        base = train + [m for m in map(mirror_sequence, train) if m is not None]
    result = evaluate(prior, base, test, samples=args.samples, temperature=args.temperature, seeds=args.seeds)
    curve = None
    if args.pca_spread:
        curve = pca_curve(train, test, cfg.length, cfg.fps, args.pca_spread, args.samples, args.seeds)
    # Sampling + export timing on the largest skeleton, CPU.
    big = max(assets, key=lambda a: a.num_joints)
    timing = default = None
    if not args.no_timing:
        timing = time_sampling(prior, big)
        # The goal is stated for the default size: time it too (speed does not depend on weights).
        default = time_sampling(PonymationPrior(MotionConfig()), big)
    out = {
        "machine": machine(),
        "torch_threads": torch.get_num_threads(),
        "command": " ".join(["bench/motion.py", *sys.argv[1:]]),
        "model": cfg.to_json(),
        "training": {
            **prior.training,
            "sequences": len(prior.training["sequences"]),
            "held_out_clips": sum(len(v) for v in held.values()),
        },
        "temperature": args.temperature if args.temperature is not None else prior.sample_temperature,
        "evaluation": {k: v for k, v in result.items() if k != "per_skeleton"},
        "per_skeleton": result["per_skeleton"],
        "sampling": timing,
        "sampling_default_size": default,
        "pca_curve": curve,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(out, indent=1) + "\n")
    widths = [max(len(c[0]), 12) for c in TABLE_COLUMNS]
    print(" | ".join(c[0].ljust(w) for c, w in zip(TABLE_COLUMNS, widths, strict=True)))
    for row in format_table(result):
        print(" | ".join(x.ljust(w) for x, w in zip(row, widths, strict=True)))
    for label, s in (("trained", timing), ("default size", default)):
        if s is None:
            continue
        print(
            f"sampling 5x60 frames, {s['joints']} joints, {label} model ({s['model']}): {s['median_sample_s']} s; "
            f"with USD+GLB export: {s['median_sample_and_export_s']} s (median of {s['repeats']})"
        )
    t = result["table"]["ponymation"]
    print(
        f"reconstruction amplitude ratio (posterior mean): training windows {t.get('train_recon_amplitude'):.3f}, "
        f"held-out {t.get('recon_amplitude'):.3f}; temperature {out['temperature']}"
    )
    for c in curve or []:
        print(f"PCA at spread {c['spread']}: MCD {c['mcd']:.2f}, diversity {c['diversity']:.3f}")
    print(f"results in {args.out}")


def train_prior(prior: PonymationPrior, data, args) -> None:
    """Train with the command line's options; writes the loss curve beside ``--out``."""
    last = [time.perf_counter()]

    def on_step(step: int, total: int, losses: dict[str, float]) -> None:
        if time.perf_counter() - last[0] > 30 or step == 1:
            last[0] = time.perf_counter()
            print(
                f"  step {step}/{total} loss {losses['total']:.4f} rot {losses['rotation']:.4f} "
                f"joints {losses['joints']:.5f} KL {losses['kl']:.1f} active {losses['active']:.0f}",
                flush=True,
            )

    opts = TrainOptions(
        epochs=args.epochs,
        batch_size=args.batch_size,
        lr=args.lr,
        max_minutes=args.minutes,
        max_steps=args.steps,
        recon_warmup=args.recon_warmup,
        kl_anneal=args.kl_anneal,
        device=args.device,
    )
    hist = prior.fit(data, opts, on_step)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_name("motion_loss.png").write_bytes(loss_curve_png(hist))
    print(f"trained {hist.steps} steps ({hist.epochs} epochs) in {hist.seconds:.0f} s", flush=True)


def time_sampling(prior: PonymationPrior, big, repeats: int = 5) -> dict:
    """Median time to sample 5 motions of 60 frames for ``big`` and export each as USD + GLB."""
    reg = get_registry()
    usd, glb = reg.exporter_for("usd"), reg.exporter_for("glb")
    tmp = Path(tempfile.mkdtemp(prefix="zooctl-bench-motion-"))
    prior.sample(big, n=1, frames=12, seed=0)  # first-call set-up (allocator, kernels) is not sampling
    times, sample_only = [], []
    for r in range(repeats):
        t = time.perf_counter()
        rots = prior.sample(big, n=5, frames=60, seed=r)
        sample_only.append(time.perf_counter() - t)
        names = [f"s{i}" for i in range(5)]
        animated = dataclasses.replace(
            big, clips={n: motion_clip(big, q, 30.0, n) for n, q in zip(names, rots, strict=True)}
        )
        for n in names:
            usd.save(animated, tmp / f"{n}.usd", clips=[n])
            glb.save(animated, tmp / f"{n}.glb", clips=[n])
        times.append(time.perf_counter() - t)
    return {
        "asset": big.name,
        "joints": big.num_joints,
        "model": f"{prior.cfg.width}x{prior.cfg.layers}",
        "samples": 5,
        "frames": 60,
        "repeats": repeats,
        "median_sample_s": round(statistics.median(sample_only), 3),
        "median_sample_and_export_s": round(statistics.median(times), 3),
    }


if __name__ == "__main__":
    main()
