"""`zooctl fit` as a library call: input, template, store record, the fit itself, outputs.

`fit_job` is what the CLI, `bench run` and the demo call. The store is touched only through
`zooctl.store.fits.FitStore` (atomic writes under the lock): a fit that is interrupted leaves its
record marked ``interrupted`` and its last state in ``state.pt`` for ``--resume``.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shlex
import shutil
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import (
    AlreadyExistsError,
    InputError,
    MissingDependencyError,
    NotFoundError,
    UsageError,
    ZooctlError,
)
from ..names import check_name, sanitize_name
from ..store.fits import FitStore
from ..video.animal_check import stored_animal_check, unsure_line
from .config import FitConfig, preset
from .focal import guessed_note, lens_note, resolve_focal
from .inputs import FitVideo, load_camera_rotations, load_fit_video, mask_notes
from .run import FitResult, Reporter, fit_video

# Marks a state saved inside a named template's start trials (`template_start`): --resume tries
# them again rather than finishing the one trial it was in.
START_TRIALS = "start_trials"


def attach_truth(video: FitVideo, folder: Path) -> None:
    """Give ``video`` the ground truth of the benchmark video in ``folder`` (`fit_job`'s
    ``truth``), its true masks as ``gt["input_masks"]``; the two must have the same frames."""
    if not (folder / "video.npz").is_file():
        raise UsageError(f"{folder} is not a `zooctl bench make` video folder (no video.npz)")
    bench = load_fit_video(folder)
    if bench.masks.shape != video.masks.shape:
        raise UsageError(
            f"{video.name} has {video.num_frames} frames of {video.size[1]}x{video.size[0]}, its truth "
            f"{bench.num_frames} of {bench.size[1]}x{bench.size[0]}",
            hint="add the benchmark's video.mp4 with all its frames at its own size",
        )
    video.gt = dict(bench.gt) | {"input_masks": bench.masks, "intrinsics": bench.intrinsics}


def load_source(
    source: str,
    store_root: Path,
    masks: str | None,
    max_frames: int | None,
    box: tuple[float, float, float, float] | None = None,
    reporter: Reporter | None = None,
) -> FitVideo:
    """A path, added to the store's video store first (see `store_video`), or a stored video's name.

    Benchmark folders (``video.npz``, with ground truth) and single images are read directly: the
    video store keeps videos of at least 2 frames and no ground truth.
    """
    p = Path(source).expanduser()
    if p.exists():
        if (p.is_dir() and (p / "video.npz").is_file()) or is_single_image(p):
            if box is not None:
                raise UsageError("--box only applies to videos segmented by GrabCut (--masks auto)")
            return load_fit_video(p, masks, max_frames)
        source = store_video(p, store_root, masks, box, reporter)
        masks = box = None  # the stored video carries its masks now
    from ..store.videos import VideoStore

    vs = VideoStore.open(store_root)
    try:
        exists = vs.exists(source)
    except Exception:
        exists = False
    if not exists:
        raise NotFoundError(
            f"{source!r} is neither a file or folder nor a stored video",
            hint="give a video file or folder, or a name from `zooctl video list`",
        )
    if masks is not None or box is not None:
        raise UsageError(
            "--masks and --box cannot replace the masks of a stored video",
            hint="re-add the video with its masks (`zooctl video add --replace`), or fit its file",
        )
    from ..store.video_reader import StoredVideo

    vs.summary(source)  # a name not in the index: NotFoundError
    rec = StoredVideo(vs.path(source))  # frames and flow stay in the file, read as the fit needs them
    n = rec.num_frames if max_frames is None else min(max_frames, rec.num_frames)
    video = FitVideo(
        source,
        rec.frames.head(n),
        rec.masks.head(n),
        float(rec.fps),
        rec.flow_forward.head(max(n - 1, 0)),
        rec.flow_valid.head(max(n - 1, 0)),
        source=f"video:{source}",
        mask_source=str(rec.segmenter.get("name", "stored")) if rec.segmenter else "stored",
        lens=rec.source.get("lens"),
        animal_check=stored_animal_check(rec),
    )
    return video.truncated(max_frames).check()


def is_single_image(p: Path) -> bool:
    from ..video.decode import IMAGE_SUFFIXES, image_files

    if p.is_file():
        return p.suffix.lower() in IMAGE_SUFFIXES
    sub = p / "JPEGImages" if (p / "JPEGImages").is_dir() else p
    return p.is_dir() and len(image_files(sub)) == 1


def store_video(
    path: Path,
    store_root: Path,
    masks: str | None,
    box: tuple[float, float, float, float] | None = None,
    reporter: Reporter | None = None,
) -> str:
    """Add the video at ``path`` to the video store, as `zooctl video add` does; returns its name.

    Masks: ``--masks DIR`` (or a mask video), ``auto`` (GrabCut, optionally seeded by ``box`` =
    x, y, w, h in original pixels around the animal in the first frame), or by default a DAVIS
    folder's ``Annotations/`` and otherwise GrabCut. A video already stored from the same source
    file with the same masks is reused (no second decode, flow and segmentation); one of the same
    name from another source or with other masks is kept, and this one gets a free name beside it.
    """
    name, reused, opts = plan_stored_video(path, store_root, masks, box)
    if reused:
        if reporter is not None:
            reporter.message(f"using the stored video {name!r}")
        return name
    if reporter is not None:
        reporter.message(f"adding {path.name} to the video store as {name!r} (decode, flow, masks)")
    return add_planned_video(
        path, store_root, masks, box, opts, None if reporter is None else reporter.message
    )


def add_planned_video(
    path: Path,
    store_root: Path,
    masks: str | None,
    box: tuple[float, float, float, float] | None,
    opts: Any,
    notify: Any = None,
) -> str:
    """Add the video at ``path`` as `plan_stored_video` planned (``opts``); returns its stored name.
    Another fit may have stored a video under that name since the plan (two fits of one file
    started together): the same video is then reused, another one gets a free name."""
    from ..store.videos import VideoStore
    from ..video.ingest import add_video

    try:
        add_video(VideoStore.open(store_root), path, opts, notify=notify)  # told what the budget kept
        return opts.name
    except AlreadyExistsError:
        name, reused, opts = plan_stored_video(path, store_root, masks, box)
        if not reused:
            add_video(VideoStore.open(store_root), path, opts)
        return name


def store_preprocessed_video(store_root: Path, video: dict[str, Any], path: Path, masks: str | None) -> str:
    """Store ``video`` (``name``, ``summary`` and the file's ``data``: what a batch worker's
    `add_video` wrote into its own store), preprocessed from ``path`` as `plan_stored_video`
    planned it with ``masks``; returns the name it is stored under. A video stored under that name
    meanwhile is reused when `plan_stored_video` finds it the same (same file, same masks); else
    this one takes the next free name (the caller renames its references)."""
    from ..store.videos import VideoStore

    vs = VideoStore.open(store_root)
    name = video["name"]
    for _ in range(3):  # again if another process takes the free name before this add
        if not vs.exists(name):
            try:
                vs.add_file(name, video["data"], video["summary"])
                return name
            except AlreadyExistsError:
                pass
        name, reused, _ = plan_stored_video(path, store_root, masks)
        if reused:
            return name
    raise UsageError(f"other zooctl processes keep storing videos named {name}", hint="run the batch again")


def plan_stored_video(
    path: Path,
    store_root: Path,
    masks: str | None,
    box: tuple[float, float, float, float] | None = None,
    taken: set[str] | None = None,
) -> tuple[str, bool, Any]:
    """The stored name of the video at ``path``: ``(name, True, opts)`` for a video stored
    already from the same file with the same masks, else ``(a free name, False, opts)`` with the
    `zooctl.video.ingest.AddOptions` to preprocess it. ``taken``: names reserved besides the store's."""
    from ..store.videos import VideoStore
    from ..video.ingest import DEFAULT_SEGMENTER, AddOptions, default_name

    opts = AddOptions(box=box)
    if masks == "auto":
        opts.segmenter = DEFAULT_SEGMENTER
    elif masks is not None:
        mp = Path(masks).expanduser()
        if not mp.exists():
            raise InputError(f"--masks {masks}: no such folder or video", hint="give mask images, or 'auto'")
        opts.masks = mp
    has_annotations = path.is_dir() and (path / "Annotations").is_dir()
    automatic = opts.masks is None and not (has_annotations and masks is None)
    segmenter = DEFAULT_SEGMENTER if automatic else "masks"
    if box is not None and not automatic:
        raise UsageError(
            "--box seeds the automatic masks: use it with --masks auto (or a video without masks)"
        )
    # What the masks segmenter records as its source: the mask folder, or the DAVIS folder itself.
    wanted_masks = str((opts.masks or path).resolve()) if segmenter == "masks" else None
    vs = VideoStore.open(store_root)
    base = default_name(path)
    resolved = str(path.resolve())
    for k in range(1, 100):
        name = base if k == 1 else f"{base}-{k}"
        if taken and name in taken:
            continue
        if not vs.exists(name):
            break
        if _same_video(vs.get(name, what=()), vs.summary(name), resolved, segmenter, wanted_masks, box):
            return name, True, opts
    else:
        raise UsageError(f"too many stored videos named {base}-N", hint="remove some with `zooctl video rm`")
    opts.name = name
    return name, False, opts


def _same_video(
    rec: Any, summary: dict[str, Any], path: str, segmenter: str, masks: str | None, box: Any
) -> bool:
    seg = rec.segmenter or {}
    if str(rec.source.get("path", "")) != path or seg.get("name") != segmenter:
        return False
    if segmenter == "masks":
        return seg.get("options", {}).get("path") == masks
    from ..video.ingest import scale_box

    stored_box = seg.get("box")  # automatic masks: the same box hint, or none on both
    if (stored_box is None) != (box is None):
        return False
    if box is None:
        return True
    original = (int(rec.source.get("original_width", 0)), int(rec.source.get("original_height", 0)))
    scaled = scale_box(box, original, (int(summary["width"]), int(summary["height"])))
    return bool(np.allclose(scaled, stored_box, atol=1))


def fit_job(
    source: str,
    store_root: Path,
    cfg: FitConfig | None = None,
    name: str | None = None,
    template: str | None = None,
    masks: str | None = None,
    out: Path | None = None,
    reporter: Reporter | None = None,
    resume: bool = False,
    exclude: set[str] | None = None,
    bank: Any = None,
    outputs: tuple[str, ...] = ("usd", "glb", "overlay", "loss"),
    box: tuple[float, float, float, float] | None = None,
    out_root: Path | None = None,
    cameras: str | None = None,
    fits: FitStore | None = None,
    replace: bool = False,
    truth: str | Path | None = None,
) -> dict[str, Any]:
    """Fit a video and write its outputs and store record; returns the record (``fit.json``).

    A name already in the store is refused unless ``replace``: then the new fit runs in a private
    folder and replaces the old one only once it has finished (a failed or interrupted run leaves
    the old fit as it was).

    ``cameras``: known camera rotations (`zooctl.fit.inputs.load_camera_rotations`: a file, or
    ``gt`` for a benchmark video's own cameras).

    ``truth``: a `zooctl bench make` folder whose ground truth scores the fit of another source
    with the same frames (its ``video.mp4`` added to the video store as a user adds a video, so
    the fit sees the store's automatic masks and flow): the 3D metrics, and the input view against
    the true masks as ``mask_iou_truth``.

    Outputs go to ``out``, else ``out_root/<name>`` (the CLI's ``fits/<name>``), else the fit's
    folder in the store. ``fits``: where the record goes instead of ``store_root``'s fits (a batch
    worker's private folder; the batch driver commits it, `zooctl.pipelines.batch_fit`)."""
    from ..store.bank import Bank
    from .template import check_bank_ready, select_template, winner_config

    fits = fits if fits is not None else FitStore(store_root)
    bank = bank if bank is not None else Bank.open(store_root)
    if name is not None and not resume:
        check_name_free(fits, check_name(name, "fit name"), replace)
    state = None
    if resume:
        if name is None:
            raise UsageError("--resume needs --name of the fit to continue")
        old = fits.get(name)
        state = fits.load_state(name)
        base = preset(state["config"].get("preset", "fast"))
        resumed = FitConfig.from_dict(state["config"], base)
        if "girth" not in state["config"].get("ablation", {}):
            resumed.ablation.girth = False  # saved before girths existed: it goes on without them
        if cfg is not None:  # the fit goes on as it started; what it writes follows this command
            resumed.texture = cfg.texture
        cfg = resumed
        source, template, masks = old["source"], old["template"], old.get("masks")
        box = tuple(old["box"]) if old.get("box") else None
        out = Path(old["out"]) if old.get("out") else out
        exclude = set(old.get("excluded", [])) or exclude
        cameras = old.get("cameras")
        truth = old.get("truth")
    cfg = (cfg or preset("fast")).validate()
    if not resume:
        check_bank_ready(bank, template)
    if template is not None and not resume:  # a resumed fit's config has the rate it started with
        cfg = cfg.for_named_template()
    if cfg.pose_prior.kind == "motion":  # the prior's folder, so the record says which one
        from ..store.motion_store import MotionStore

        folder = str(MotionStore.open(store_root).resolve(cfg.pose_prior.motion))
        cfg = dataclasses.replace(cfg, pose_prior=dataclasses.replace(cfg.pose_prior, motion=folder))
    t_start = time.perf_counter()
    video = load_source(source, store_root, masks, cfg.max_frames, box, reporter)
    try:
        if truth is not None:
            attach_truth(video, Path(truth))
        if resume and old.get("focal"):
            focal = old["focal"]  # the saved config holds the focal it started with
        else:
            cfg, focal = resolve_focal(cfg, video)
        if cameras is not None and not resume:  # a resumed fit's camera search is done already
            video.camera_rotations = load_camera_rotations(cameras, video)
            if cameras != "gt":
                cameras = str(Path(cameras).expanduser().resolve())
        name = check_name(name or sanitize_name(video.name), "fit name")
        replacing = not resume and not check_name_free(fits, name, replace)
        t_ret = time.perf_counter()
        if resume and state is not None:
            asset = bank.get(template)  # the template chosen (and tried) when the fit started
            candidates, t_trials = fits.get(name).get("retrieval", []), None
        else:
            asset, candidates, state, t_trials = select_template(
                bank, template, video, cfg, exclude=exclude, reporter=reporter
            )
            cfg = winner_config(cfg, candidates, asset.name)
        t_ret = time.perf_counter() - t_ret - (t_trials or 0.0)
        if out is not None:
            out_dir = Path(out)
        else:
            out_dir = Path(out_root) / name if out_root is not None else fits.path(name)
        out_dir = out_dir.resolve()  # the record names its files by absolute paths
        final_fits, final_out, staged = fits, out_dir, None
        if replacing:  # the old fit and its outputs stay until the new fit is committed
            staged = fits.staging(name)
            fits = FitStore(staged)
            in_store = final_out == final_fits.path(name).resolve()
            out_dir = (fits.path(name) if in_store else staged / "out").resolve()
        try:
            out_dir.mkdir(parents=True, exist_ok=True)
            record: dict[str, Any] = {
                "status": "running",
                "source": str(source),
                "video": video.name,
                "masks": masks,
                "cameras": cameras,
                "truth": str(Path(truth).resolve()) if truth is not None else None,
                "focal": focal,
                "box": list(box) if box is not None else None,
                "stored_video": video.source[len("video:") :] if video.source.startswith("video:") else None,
                "mask_source": video.mask_source,
                "frames": video.num_frames
                if cfg.max_frames is None
                else min(cfg.max_frames, video.num_frames),
                "image_size": list(video.size),
                "fps": video.fps,
                "template": asset.name,
                "retrieval": candidates,
                "excluded": sorted(exclude or []),
                "out": str(out_dir.resolve()),
                "config": cfg.to_dict(),
                "outputs": {},
            }
            fits.save_record(name, record)
            from ..store.fs import write_json_atomic

            write_json_atomic(fits.path(name) / "config.json", cfg.to_dict())

            def checkpoint(st: dict[str, Any]) -> None:
                fits.save_state(name, st)

            record = _run_and_write(
                video,
                asset,
                cfg,
                reporter,
                checkpoint,
                state,
                template,
                candidates,
                source,
                out_dir,
                fits,
                name,
                outputs,
                record,
                t_ret,
                t_trials,
                t_start,
            )
        except BaseException:
            if staged is not None:
                shutil.rmtree(staged, ignore_errors=True)
            raise
        if staged is not None:
            record = _commit_replacement(final_fits, name, staged, fits.path(name), out_dir, final_out)
        return record | {"name": name}
    finally:
        video.close()  # the stored video's file, now, not when the collector finds it


def check_name_free(fits: FitStore, name: str, replace: bool) -> bool:
    """True when no fit is called ``name``; False when one is and ``replace`` allows a new one."""
    if not fits.exists(name):
        return True
    if replace:
        return False
    try:
        status = fits.get(name).get("status", "unknown")
    except ZooctlError:
        status = "unreadable"
    raise AlreadyExistsError(
        f"a fit named {name!r} exists already (status {status})",
        hint=f"--replace fits it again (the old fit stays until the new one finishes), --resume "
        f"continues an interrupted one, --name picks another name, or `zooctl fits rm {name}`",
    )


def _commit_replacement(
    fits: FitStore, name: str, staged: Path, staged_fit: Path, staged_out: Path, final_out: Path
) -> dict[str, Any]:
    """Move a finished private fit into the store in place of the old one: the record and fit.json
    rebased to the final paths, outputs outside the store published, then the folders swapped."""
    from ..store.fits import rebase_paths
    from ..store.fs import json_bytes, temp_path

    final_fit = fits.path(name).resolve()
    moves = [(str(staged_out), str(final_out)), (str(staged_fit.resolve()), str(final_fit))]

    def rebased(doc: Any) -> Any:
        for old, new in moves:
            doc = rebase_paths(doc, old, new)
        return doc

    record = rebased(json.loads((staged_fit / "record.json").read_text()))
    (staged_fit / "record.json").write_bytes(json_bytes(record))
    inside = staged_out == staged_fit.resolve()
    pending: list[tuple[Path, Path]] = []
    try:
        for p in sorted(staged_out.rglob("*")) if staged_out.is_dir() else []:
            if not p.is_file():
                continue
            data = p.read_bytes()
            if p.name == "fit.json":
                data = json_bytes(rebased(json.loads(data)))
            if inside:
                p.write_bytes(data)
                continue
            dest = final_out / p.relative_to(staged_out)
            tmp = temp_path(dest)
            tmp.write_bytes(data)
            pending.append((tmp, dest))

        def publish_outputs() -> None:
            for tmp, dest in pending:
                os.replace(tmp, dest)

        fits.replace_with(name, staged_fit, publish_outputs)
    finally:
        for tmp, _ in pending:
            tmp.unlink(missing_ok=True)
        shutil.rmtree(staged, ignore_errors=True)
    return record


def _run_and_write(
    video: Any,
    asset: Any,
    cfg: FitConfig,
    reporter: Reporter | None,
    checkpoint: Any,
    state: Any,
    template: str | None,
    candidates: list[Any],
    source: str,
    out_dir: Path,
    fits: FitStore,
    name: str,
    outputs: tuple[str, ...],
    record: dict[str, Any],
    t_ret: float,
    t_trials: float | None,
    t_start: float,
) -> dict[str, Any]:
    from .named_start import template_start

    mirror_s = None
    try:
        if state is None or START_TRIALS in state:
            # no template trial ran: a named template's start is tried here (its depth mirror,
            # and with `camera.start_trial` its steady track). A fit stopped inside these trials
            # tries them all again on --resume: a trial's state alone cannot say which start the
            # comparison would have kept.
            given = template is not None if state is None else bool(state[START_TRIALS]["template_given"])
            marked = None
            if checkpoint is not None:

                def marked(st: dict[str, Any]) -> None:  # resumed with the fit's config, not the trial's
                    checkpoint({**st, "config": cfg.to_dict(), START_TRIALS: {"template_given": given}})

            kept = template_start(video, asset, cfg, given, reporter, marked)
            state = None if kept is None else kept.state
            if kept is not None:
                mirror_s = kept.view.get("extra_seconds")
                if state is not None and checkpoint is not None and cfg.checkpoint_every:
                    checkpoint(state)  # the saved state is the kept start's, not the last one tried
        result = fit_video(video, asset, cfg, reporter, checkpoint, state)
    except KeyboardInterrupt:
        record["status"] = "interrupted"
        fits.save_record(name, record)
        raise
    except Exception as exc:  # listed as failed, not as running forever
        record["status"] = "failed"
        record["error"] = (exc.message if isinstance(exc, ZooctlError) else f"{type(exc).__name__}: {exc}")[
            :500
        ]
        fits.save_record(name, record)
        raise
    result.timings["retrieval"] = t_ret
    if t_trials is not None:
        result.timings["template_trials"] = t_trials
    if mirror_s is not None:
        result.timings["mirror_trial"] = mirror_s
    record.update(write_outputs(result, name, out_dir, fits, outputs, reporter))
    if template is None:
        from .template import close_trials_note

        note = close_trials_note(candidates, asset.name, shlex.quote(str(source)))
        record["notes"] = ([note] if note else []) + record["notes"]
    if record["focal"]["from"] == "estimated":
        record["focal"]["px"] = record["camera"]["focal_px"]
    focal_line = lens_note(record["focal"]) or guessed_note(record["focal"], video.size[0])
    if focal_line:
        record["notes"] = [focal_line] + record["notes"]
    record["notes"] = mask_notes(video.truncated(cfg.max_frames).masks) + record["notes"]
    unsure = unsure_line(video.animal_check, video.name)
    if unsure:
        record["notes"] = [unsure.removeprefix("warning: ")] + record["notes"]
    record["timings"]["total_wall"] = time.perf_counter() - t_start
    record["status"] = "done"
    from .outputs import write_fit_json

    write_fit_json(record | {"name": name, "schema_version": 1}, out_dir / "fit.json")
    record["outputs"]["fit_json"] = str(out_dir / "fit.json")
    fits.save_record(name, record)
    return record


def write_outputs(
    result: FitResult,
    name: str,
    out_dir: Path,
    fits: FitStore,
    outputs: tuple[str, ...],
    reporter: Reporter | None,
) -> dict[str, Any]:
    """Character, USD, GLB, overlay video, loss plot and metrics; the record fields they fill."""
    from .fitted_asset import fitted_asset
    from .outputs import (
        TORN_NOTE_WEIGHT,
        bake_colours,
        exported_mask_iou,
        stage_summary,
        surface_tear,
        surface_tear_note,
        write_glb,
        write_loss_png,
        write_overlay,
        write_usd,
    )

    t = time.perf_counter()
    asset = fitted_asset(
        result.scene,
        result.template,
        name,
        result.video.fps,
        {"source": f"zooctl fit of {result.video.name}"},
    )
    # Before the bake, whose atlas splits vertices: the template's vertices tell which are copies.
    same = result.template.vertices.shape == asset.vertices.shape
    tear = surface_tear(asset, seams=result.template.vertices if same else None)
    cam = result.input_camera().to("cpu")  # the outputs pose and render the exported asset on the CPU
    texture = None
    if result.config.texture:
        if reporter is not None:
            reporter.message("baking the video's colours onto the character")
        asset, texture = bake_colours(asset, cam, result.video, result.template)
        result.timings["texture"] = texture.pop("seconds")
    fits.save_character(name, asset)  # with its baked colours: `fits export` writes them again
    files: dict[str, str] = {}
    notes: list[str] = []
    if "usd" in outputs:
        files["usd"] = str(write_usd(asset, cam, out_dir / f"{name}.usd"))
    if "glb" in outputs:
        try:
            files["glb"] = str(write_glb(asset, out_dir / f"{name}.glb"))
        except MissingDependencyError as exc:
            notes.append(f"glb not written: {exc.message}")
    if "overlay" in outputs:
        if reporter is not None:
            reporter.message("rendering overlay.mp4")
        files["overlay"] = str(
            write_overlay(asset, cam, result.video.frames, out_dir / "overlay.mp4", result.video.fps)
        )
    if "loss" in outputs:
        files["loss_png"] = str(write_loss_png(result.history, out_dir / "loss.png"))
    result.timings["outputs"] = time.perf_counter() - t
    # What the user gets: the exported mesh (LBS of the written asset) at the input resolution.
    iou = exported_mask_iou(asset, cam, result.video.masks)
    model_iou = result.iou if result.iou is not None else np.array([np.nan])
    metrics: dict[str, Any] = {
        "mask_iou": _nanmean(iou),
        "mask_iou_per_frame": [None if not np.isfinite(x) else round(float(x), 4) for x in iou],
        "mask_iou_measured": (
            "exported mesh (fit clip of the USD/GLB character) projected through the fitted camera at the "
            f"input resolution {result.video.size[1]}x{result.video.size[0]}, against the video's stored "
            f"masks ({result.video.mask_source})"
        ),
        "mask_iou_model": _nanmean(model_iou),
        "surface_tear": round(tear, 5),
    }
    if "input_masks" in result.video.gt:  # a fit on other masks, scored against the truth's
        metrics["mask_iou_truth"] = _nanmean(exported_mask_iou(asset, cam, result.video.gt["input_masks"]))
    weight = result.config.weights.edge_stretch
    note = surface_tear_note(metrics["surface_tear"], weight) if weight < TORN_NOTE_WEIGHT else None
    if note is not None:
        notes.append(note)
    if result.video.gt:
        from .metrics import evaluate_fit

        views: list = []
        try:
            metrics.update(
                {
                    k: (None if isinstance(v, float) and not np.isfinite(v) else v)
                    for k, v in evaluate_fit(result, views=views).items()
                }
            )
        except InputError as exc:
            notes.append(f"3D metrics skipped: {exc.message}")
        if views and "frames_evaluated" in metrics:  # the metrics finished
            from .outputs import write_novel_view_png

            path = out_dir / "novel_view.png"
            files["novel_view_png"] = str(write_novel_view_png(views, metrics["frames_evaluated"], path))
    k = result.scene.camera(1).intrinsics[0].detach().cpu().numpy() / result.scale
    return {
        "outputs": files,
        "notes": notes,
        "camera": {
            "convention": "static camera at the world origin looking down -Z, +Y up (USD /World/Camera, identity transform)",
            "focal_px": float(k[0]),
            "image_size": list(result.video.size),
            "search": result.camera_init,
        },
        "losses": stage_summary(result.history),
        "timings": {k: round(float(v), 3) for k, v in result.timings.items()},
        "metrics": metrics,
        "texture": texture,
        "fitted": {
            "global_scale": float(result.scene.model.global_scale().detach()),
            "bone_scales": [round(float(b), 4) for b in result.scene.model.bone_scales().detach().cpu()],
        },
    }


def _nanmean(a: np.ndarray) -> float | None:
    a = np.asarray(a, dtype=np.float64)
    return float(np.nanmean(a)) if np.isfinite(a).any() else None
