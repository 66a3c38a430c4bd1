"""`zooctl motion train` as a library call: gather motion (bank clips, fitted videos), train any
registered motion prior, publish it in the motion store.

`MotionTrainOptions` holds every default (the CLI passes only what the user set). The model size,
batch and time budget follow the device (`device_defaults`): Ponymation's 256 x 4 on CUDA, a
smaller model a CPU trains well in its time budget otherwise; `resolve` says which it picked.
"""

from __future__ import annotations

import dataclasses
import inspect
import json
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from ..errors import UsageError

# On a CPU the paper's 256 x 4 gets too few steps in the time budget and stays near the mean
# pose; the per-bone trajectory model at 64 x 2 gets many more steps than the per-frame one and
# reconstructs more of the motion (BENCHMARKS.md, Motion prior).
CPU_SIZE = {"arch": "trajectory", "width": 64, "layers": 2, "batch_size": 32, "lr": 1e-3, "max_minutes": 20.0}
CUDA_SIZE = {
    "arch": "ponymation",
    "width": 256,
    "layers": 4,
    "batch_size": 64,
    "lr": 3e-4,
    "max_minutes": 20.0,
}


@dataclass
class MotionTrainOptions:
    """What to train and how; None means "follow the device" (`device_defaults`)."""

    kind: str = "ponymation"
    arch: str | None = None  # ponymation's model: "ponymation" (per-frame) or "trajectory" (per-bone)
    width: int | None = None
    layers: int | None = None
    latent: int | None = None  # default: the width
    length: int | None = None  # frames per window; default: the prior's own
    epochs: int = 1000
    max_minutes: float | None = None
    max_steps: int | None = None  # a fixed amount of work: the schedules follow it where it ends first
    batch_size: int | None = None
    lr: float | None = None
    kl_weight: float | None = None  # default: the model's (`MotionConfig`)
    free_bits: float | None = None
    holdout: float = 0.0
    seed: int = 0
    device: str = "cpu"
    threads: int | None = None

    def resolve(self) -> tuple[MotionTrainOptions, str]:
        """A copy with every device-dependent default filled in, and a line saying what was picked."""
        dev = device_defaults(self.device)
        filled = {k: (v if getattr(self, k) is None else getattr(self, k)) for k, v in dev.items()}
        out = dataclasses.replace(self, **filled)
        if out.latent is None:
            out.latent = out.width
        if out.kind != "ponymation":
            return out, f"{out.kind} on {self.device}"
        picked = [k for k in ("arch", "width", "layers") if getattr(self, k) is None]
        why = (
            "Ponymation's model on CUDA" if self.device.startswith("cuda") else "the model a CPU trains well"
        )
        note = (
            f"{out.arch} {out.width} x {out.layers}, batch {out.batch_size}, lr {out.lr:g}, "
            + (f"{out.max_steps} steps or " if out.max_steps else "")
            + f"{out.max_minutes:g} min budget on {self.device}"
            + (f": {why}" if picked else "")
        )
        return out, note


def device_defaults(device: str) -> dict[str, Any]:
    return dict(CUDA_SIZE if str(device).startswith("cuda") else CPU_SIZE)


def gather_sequences(
    store_root: Path,
    assets: list[str] | None = None,
    all_assets: bool = False,
    fits: list[str] | None = None,
    all_fits: bool = False,
) -> tuple[list[Any], list[Any]]:
    """(bank assets with clips, motion sequences of the fits) to train on. Fits made from the same
    template share one skeleton, so their windows pool like one asset's clips."""
    from ..store.bank import Bank
    from ..store.fits import FitStore

    wanted, fit_names = list(assets or []), list(fits or [])
    if all_assets and wanted:
        raise UsageError("give --assets or --all, not both", hint="zooctl motion train --all")
    if all_fits and fit_names:
        raise UsageError("give --fits or --all-fits, not both", hint="zooctl motion train --all-fits")
    if not (wanted or all_assets or fit_names or all_fits):
        raise UsageError(
            "name what to train on: --assets, --all (bank clips), --fits or --all-fits (fitted videos)",
            hint="zooctl motion train --all",
        )
    loaded = []
    if wanted or all_assets:
        bank = Bank.open(store_root)
        for n in bank.names() if all_assets else wanted:
            a = bank.get(n)
            if a.clips:
                loaded.append(a)
            elif not all_assets:
                raise UsageError(
                    f"asset {n!r} has no animation clips to learn from",
                    hint="pick assets with clips (`zooctl bank list`)",
                )
        if not loaded and not (fit_names or all_fits):
            raise UsageError(
                "no bank asset with animation clips to train on",
                hint="add some: zooctl bank add FILE.glb, or zooctl bank seed",
            )
    seqs: list[Any] = []
    if fit_names or all_fits:
        fs = FitStore(store_root)
        names = fs.names() if all_fits else fit_names
        seqs = fit_sequences(fs, names, skip_unfinished=all_fits)
        if not seqs:
            raise UsageError("no finished fit to train on", hint="fit a video first: zooctl fit VIDEO")
    return loaded, seqs


def fit_sequences(fits: Any, names: list[str], skip_unfinished: bool = False) -> list[Any]:
    """The fitted motion of each named fit (its character's ``fit`` clip) as `MotionSequence`s."""
    from ..errors import NotFoundError
    from ..motion.dataset import sequence_from_clip
    from ..motion.skeleton import Skeleton

    shared: dict[tuple[str, int], Skeleton] = {}
    out = []
    for n in names:
        rec = fits.get(n)
        try:
            character = fits.character(n)
        except NotFoundError:
            if skip_unfinished:
                continue
            raise
        if "fit" not in character.clips:
            raise UsageError(f"fit {n!r} has no fitted motion", hint="fit it again")
        own = Skeleton.from_asset(character)
        seq = sequence_from_clip(character, "fit", own)
        group = (str(rec.get("template", n)), own.num_joints)
        seq.skeleton = shared.setdefault(group, own)
        seq.name, seq.source = f"fit:{n}", "fit"
        out.append(seq)
    return out


def train_motion_prior(
    store_root: Path,
    name: str,
    opts: MotionTrainOptions,
    assets: list[Any],
    extra_sequences: list[Any] | None = None,
    replace: bool = False,
    on_step: Callable[[int, int, dict[str, float]], None] | None = None,
    log: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Train a prior of kind ``opts.kind`` on the clips of ``assets`` (minus the held-out ones)
    and ``extra_sequences``; publish it as ``name``. Returns its config.json plus ``path``."""
    from ..motion.evaluate import split_assets
    from ..names import check_name
    from ..plugins import get_registry
    from ..store.motion_store import MotionStore

    check_name(name, "motion prior name")
    store = MotionStore.open(store_root)
    if store.exists(name) and not replace:
        raise store._exists(name)
    spec = get_registry().get("motion_prior", opts.kind)
    opts, note = opts.resolve()
    if opts.threads:
        import torch

        torch.set_num_threads(opts.threads)
    train_seqs, _, held = split_assets(assets, opts.holdout, opts.seed)
    train_seqs = train_seqs + list(extra_sequences or [])
    prior = spec.create(device=opts.device, **_model_options(opts))
    if log:
        log(f"training {name!r}: {len(assets)} assets, {len(extra_sequences or [])} fits, {note}")
    hist = _fit(prior, train_seqs, opts, on_step)
    training = getattr(prior, "training", None)
    if isinstance(training, dict):
        training.update(
            {"assets": sorted(a.name for a in assets), "holdout": held, "seed": opts.seed, "size": note}
        )
    extra = {"created": datetime.now(timezone.utc).isoformat(timespec="seconds")}

    def write(tmp: Path) -> None:
        _save(prior, tmp, name, opts.kind, extra)
        if hist is not None and hasattr(hist, "total"):
            from ..motion.train import loss_curve_png

            (tmp / "loss.png").write_bytes(loss_curve_png(hist))
            cfg = json.loads((tmp / "config.json").read_text())
            cfg["files"] = {**cfg.get("files", {}), "loss_curve": "loss.png"}
            (tmp / "config.json").write_text(json.dumps(cfg, indent=1, sort_keys=True) + "\n")

    path = store.add(name, write, replace=replace)
    return {"path": str(path), **store.config(name)}


def _model_options(opts: MotionTrainOptions) -> dict[str, Any]:
    out: dict[str, Any] = {} if opts.length is None else {"length": opts.length}
    if opts.kind == "ponymation":
        out.update({"width": opts.width, "layers": opts.layers, "latent": opts.latent})
        if opts.arch is not None:
            out["arch"] = opts.arch
        out.update({k: getattr(opts, k) for k in ("kl_weight", "free_bits") if getattr(opts, k) is not None})
    return out


def _fit(prior: Any, seqs: list[Any], opts: MotionTrainOptions, on_step) -> Any:
    """``prior.fit`` with the training options and progress callback it accepts."""
    params = inspect.signature(prior.fit).parameters
    kw: dict[str, Any] = {}
    if "options" in params:
        from ..motion.train import TrainOptions

        kw["options"] = TrainOptions(
            epochs=opts.epochs,
            batch_size=opts.batch_size,
            lr=opts.lr,
            max_minutes=opts.max_minutes,
            max_steps=opts.max_steps,
            seed=opts.seed,
            device=opts.device,
        )
    if "on_step" in params:
        kw["on_step"] = on_step
    return prior.fit(seqs, **kw)


def _save(prior: Any, tmp: Path, name: str, kind: str, extra: dict[str, Any]) -> None:
    """Save through the prior; make sure ``config.json`` names the prior and its plugin."""
    params = inspect.signature(prior.save).parameters
    if "extra" in params:
        prior.save(tmp, name, extra)
    else:
        prior.save(tmp)
    p = tmp / "config.json"
    cfg = json.loads(p.read_text()) if p.is_file() else {}
    cfg.setdefault("schema_version", 1)
    cfg.setdefault("training", getattr(prior, "training", {}) or {})
    cfg.setdefault("files", {})
    cfg.update({"name": name, "plugin": kind, **extra})
    p.write_text(json.dumps(cfg, indent=1, sort_keys=True) + "\n")
