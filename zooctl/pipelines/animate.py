"""`zooctl animate`: sample motions from a stored prior for a character and export them.

The character is a bank asset, a finished fit (its fitted character, from the fit store), or a
single photo that is fitted first (`fit_image`: CASA on one frame, then sampled like any fit).
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..asset import RiggedAsset
from ..errors import NotFoundError, UsageError

FIT_PREFIX = "fit:"


@dataclass
class AnimateOptions:
    sample: int = 5
    frames: int = 60
    seed: int = 0
    temperature: float | None = None  # default: the prior's `sample_temperature`
    prior: str | None = None  # default: the most recently trained
    formats: tuple[str, ...] = ("usd", "glb")
    preview: bool = True
    size: int = 128
    preview_fps: float = 5.0  # frames per second the preview renders (rendering dominates the command)
    device: str = "cpu"


def resolve_target(store_root: Path, target: str) -> tuple[Any, str]:
    """(character, kind) for a bank asset name, ``fit:NAME``, or a fit name no bank asset has."""
    from ..store.bank import Bank
    from ..store.fits import FitStore

    fits = FitStore(store_root)
    if target.startswith(FIT_PREFIX):
        return fits.character(target[len(FIT_PREFIX) :]), "fit"
    bank = Bank.open(store_root)
    if target in bank.names():
        return bank.get(target), "asset"
    if fits.exists(target):
        return fits.character(target), "fit"
    raise NotFoundError(
        f"{target!r} is neither a bank asset nor a fit",
        hint="see `zooctl bank list` and `zooctl fits list`, or animate a photo with --image",
    )


def fit_image(
    image: Path,
    store_root: Path,
    masks: str | None = None,
    template: str | None = None,
    config: Path | None = None,
    device: str = "cpu",
    reporter: Any = None,
) -> tuple[Any, str]:
    """Fit one photo (CASA on a single frame; the fast preset, with ``config``, a JSON file, on
    top) and return (fitted character, fit name)."""
    from ..fit.config import load_config
    from ..fit.job import fit_job
    from ..store.fits import FitStore
    from ..video.decode import IMAGE_SUFFIXES

    image = Path(image).expanduser()
    if not image.is_file() or image.suffix.lower() not in IMAGE_SUFFIXES:
        raise UsageError(
            f"--image {image}: not an image file",
            hint=f"give a photo ({', '.join(sorted(IMAGE_SUFFIXES))}) and its mask with --masks DIR",
        )
    cfg = load_config(config, "fast")
    cfg.device = device
    rec = fit_job(
        str(image),
        store_root,
        cfg,
        template=template,
        masks=masks,
        reporter=reporter,
        outputs=("loss",),
        replace=True,
    )
    return FitStore(store_root).character(rec["name"]), rec["name"]


def sample_and_export(
    asset: RiggedAsset, label: str, out: Path, opts: AnimateOptions, store_root: Path
) -> dict[str, Any]:
    """Sample ``opts.sample`` motions for ``asset``, write one file per motion and format, the
    preview video and contact sheet, and ``animate.json``; returns that manifest."""
    from ..io.asset_export import resolve_export
    from ..io.export_worker import ExportWorker
    from ..store.fs import write_bytes_atomic
    from ..store.motion_store import MotionStore

    # Every format resolved before any sampling: an unknown one is an error up front.
    specs = {f: resolve_export(None, f, label)[0] for f in opts.formats}
    # The exporters load their libraries in a second process while this one imports PyTorch and
    # samples, and write the files while it renders the preview.
    with ExportWorker(specs.values()) as worker:
        from ..motion.prior import motion_clip

        t0 = time.perf_counter()
        store = MotionStore.open(store_root)
        prior_name = opts.prior or store.latest()
        prior = store.load(prior_name, device=opts.device)
        # Not every prior plugin takes a temperature: pass it only when asked for.
        options = {"temperature": opts.temperature} if opts.temperature is not None else {}
        rots = prior.sample(
            asset, n=opts.sample, frames=opts.frames, seed=opts.seed, **options
        )  # (n, T, J, 4)
        t_sample = time.perf_counter() - t0
        fps = float(getattr(getattr(prior, "cfg", None), "fps", 30.0))
        names = [f"sample{i:02d}" for i in range(opts.sample)]
        animated = dataclasses.replace(
            asset, clips={n: motion_clip(asset, r, fps, n) for n, r in zip(names, rots, strict=True)}
        )
        out.mkdir(parents=True, exist_ok=True)
        files: dict[str, list[str]] = {f: [] for f in opts.formats}
        jobs = []
        for n in names:
            for f, spec in specs.items():
                path = out / f"{label}_{n}{spec.suffix_for(f)}"
                jobs.append((spec, path, [n]))
                files[f].append(str(path))
        exports = worker.submit(animated, jobs)
        if opts.preview:
            files.update(
                _preview(animated, names, out, label, opts.size, fps, opts.device, asset, opts.preview_fps)
            )
        t_export = exports.result()
    manifest = {
        "target": label,
        "amplitude_deg": [round(motion_amplitude(asset, r), 2) for r in rots],
        "prior": prior_name,
        "samples": opts.sample,
        "frames": opts.frames,
        "fps": fps,
        "seed": opts.seed,
        "temperature": opts.temperature
        if opts.temperature is not None
        else getattr(prior, "sample_temperature", None),
        "files": files,
        "seconds": {
            "sample": round(t_sample, 3),
            # the writing's own time: it ran beside the preview
            "export": round(t_export, 3),
            "sample_and_export": round(t_sample + t_export, 3),
            "total": round(time.perf_counter() - t0, 3),
        },
    }
    write_bytes_atomic(out / "animate.json", (json.dumps(manifest, indent=1) + "\n").encode())
    return manifest


def motion_amplitude(asset, rotations: np.ndarray) -> float:
    """Mean over joints of how far each turns from its first pose (degrees): local rotations
    (T, J, 4) of ``asset`` -> a number (~0 for a statue; `zooctl.motion.metrics.joint_amplitude`)."""
    from ..motion import metrics as M
    from ..motion.dataset import quat_conj, quat_mul
    from ..motion.skeleton import Skeleton

    rest = Skeleton.from_asset(asset).rest_rotations
    return float(M.joint_amplitude(quat_mul(quat_conj(rest)[None, None], rotations[None])).mean())


def reference_clip(asset) -> str | None:
    """The asset's own clip that moves most (a fit's ``fit`` clip, a bank asset's walk or
    gallop...), shown beside the samples; None when it has none."""
    if not asset.clips:
        return None
    return max(asset.clips, key=lambda c: motion_amplitude(asset, asset.clips[c].rotations))


def _preview(
    asset,
    clips: list[str],
    out: Path,
    label: str,
    size: int,
    fps: float,
    device: str,
    original=None,
    preview_fps: float = 5.0,
) -> dict[str, list[str]]:
    """A video with every sample in motion beside a real clip of the same skeleton (``original``'s
    most moving clip, looped), and a contact sheet (one row of frames per sample) whose labels give
    each motion's amplitude (mean degrees a joint turns from the first frame). Every
    ``fps / preview_fps``-th frame is rendered and the video plays them at ``preview_fps``: same
    duration and motion, a fraction of the rendering."""
    import dataclasses

    from ..io.video import write_mp4
    from ..render.preview import contact_sheet, render_asset, save_png

    T = asset.clips[clips[0]].num_frames
    step = max(1, int(round(fps / preview_fps))) if preview_fps > 0 else 1
    shown = list(range(0, T, step))
    amp = {c: motion_amplitude(asset, asset.clips[c].rotations) for c in clips}
    videos = [render_asset(asset, c, frames=shown, size=size, supersample=1, device=device) for c in clips]
    names = [f"{c} {amp[c]:.1f} deg" for c in clips]
    ref = reference_clip(original) if original is not None else None
    if ref is not None:
        # The real clip played with the samples' skeleton: same size and framing as they are.
        real = dataclasses.replace(asset, clips={ref: original.clips[ref]})
        n = real.clips[ref].num_frames
        videos.insert(
            0,
            render_asset(real, ref, frames=[t % n for t in shown], size=size, supersample=1, device=device),
        )
        ref_amp = motion_amplitude(original, original.clips[ref].rotations)
        names.insert(0, f"real {ref.split('|')[-1]} {ref_amp:.1f} deg")
    cols = min(len(videos), 6)
    grid = [contact_sheet([v[i] for v in videos], labels=names, columns=cols) for i in range(len(shown))]
    video = write_mp4(out / f"{label}_samples.mp4", np.stack(grid), fps=fps / step)
    picks = np.linspace(0, len(shown) - 1, min(len(shown), 6)).round().astype(int)
    tiles = [v[i] for v in videos for i in picks]
    labels = [f"{nm} f{shown[i]}" if i == picks[0] else f"f{shown[i]}" for nm in names for i in picks]
    sheet = save_png(
        out / f"{label}_contact_sheet.png", contact_sheet(tiles, labels=labels, columns=len(picks))
    )
    return {"preview": [str(video)], "contact_sheet": [str(sheet)]}
