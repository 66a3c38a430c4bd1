"""`zooctl fit VIDEO...` and `bench run --executor`: one fit per task, committed by the driver.

Where things live:

- a worker reads the store (the bank, stored videos) and the input files by path, so it needs
  them on a shared file system at the same path (or a copy of them there); it never writes them;
- it fits into a private temporary folder on its own disk (a video file is decoded, its flow and
  masks computed there too, streamed into a video store of its own) and returns the fit's files
  as bytes (and the new stored video's file): results travel back through the executor, not the
  file system;
- the driver writes them: the stored video (`VideoStore.add_file`), the output folder, and the fit's
  store folder under the store's lock with ``record.json`` last, so a fit exists only complete.
"""

from __future__ import annotations

import glob
import json
import shlex
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import InputError, UsageError, ZooctlError
from ..names import check_name, sanitize_name
from .batch import BatchItem
from .worker_scratch import claim, release, scratch_path, sweep_orphans

_GLOB_CHARS = set("*?[")
# Fits that share one GPU when the user does not say (--gpus-per-task): a fit leaves the device
# idle most of each step, and four on one H100 took about the time of one (BENCHMARKS.md, CUDA:
# "Several fits on one GPU").
FITS_PER_GPU = 4
# Memory a fit at once takes by default on the CPU (GB): its peak RSS is about 0.9 GB for a
# 60-frame 320 px video and 1.1 GB for a 60 s 1080p clip fitted in windows (BENCHMARKS.md, Fit).
FIT_MEMORY_GB = 1.5


@dataclass
class FitTask:
    """One fit, as it travels to a worker."""

    store: str  # store root: read by the worker (bank, stored videos), written by the driver only
    source: str  # stored video name, benchmark folder, image, or video file (see ``ingest``)
    name: str
    config: dict[str, Any]  # FitConfig.to_dict()
    template: str | None = None
    exclude: tuple[str, ...] | None = None
    ingest: Any = None  # AddOptions: the worker decodes ``source`` and computes flow and masks
    masks: str | None = None  # --masks as `plan_stored_video` planned ``ingest`` with it (None, "auto")
    outputs: tuple[str, ...] = ("usd", "glb", "overlay", "loss")
    cameras: str | None = None
    out: str | None = None  # final output folder (None: the fit's store folder)


def expand_inputs(args: list[str]) -> list[str]:
    """Paths, globs (quoted, for zooctl to expand) and stored names, in order, without repeats."""
    out: list[str] = []
    for a in args:
        if not Path(a).expanduser().exists() and _GLOB_CHARS & set(a):
            hits = sorted(glob.glob(str(Path(a).expanduser())))
            if not hits:
                raise InputError(f"{a}: no file matches", hint="check the pattern (quote it for zooctl)")
            out += hits
        else:
            out.append(a)
    return list(dict.fromkeys(out))


def plan_fits(
    sources: list[str],
    store_root: Path,
    config: dict[str, Any],
    template: str | None = None,
    masks: str | None = None,
    out_root: Path | None = None,
    cameras: str | None = None,
    keep_existing: bool = True,
) -> list[BatchItem]:
    """One item per input: its fit name, and whether a worker must first decode and store it.

    Names follow `zooctl fit`: the video's name, with ``-2``, ``-3`` ... for a second input of
    the same name in this batch. A name the store already has is refused up front while
    ``keep_existing`` (no ``--replace`` or ``--resume``); the old fit is never touched then."""
    from ..fit.job import check_name_free, is_single_image, plan_stored_video
    from ..store.fits import FitStore

    fits = FitStore(store_root)

    if masks not in (None, "auto"):
        raise UsageError(
            "--masks DIR is one video's masks", hint="fit several videos with --masks auto, or none"
        )
    items: list[BatchItem] = []
    names: set[str] = set()
    videos: set[str] = set()  # stored-video names this batch will add
    for src in sources:
        p = Path(src).expanduser()
        task = FitTask(str(store_root), src, "", config, template=template, cameras=cameras, masks=masks)
        try:
            if p.exists() and ((p.is_dir() and (p / "video.npz").is_file()) or is_single_image(p)):
                task.source, base = str(p.resolve()), _bench_name(p)
            elif p.exists():
                vname, reused, opts = plan_stored_video(p, store_root, masks, None, taken=videos)
                if not reused:
                    videos.add(vname)
                    task.source, task.ingest = str(p.resolve()), opts
                else:
                    task.source = vname
                base = vname
            else:
                base = src  # a stored video's name: the worker says if there is none
            base = sanitize_name(base)
            name = next(n for n in [base] + [f"{base}-{k}" for k in range(2, 1000)] if n not in names)
            task.name = check_name(name, "fit name")
            check_name_free(fits, task.name, not keep_existing)
        except ZooctlError as exc:
            items.append(BatchItem(sanitize_name(p.name or src), task, src, error=exc))
            continue
        names.add(task.name)
        task.out = str((out_root / task.name).resolve()) if out_root is not None else None
        items.append(BatchItem(task.name, task, src))
    return items


def _bench_name(p: Path) -> str:
    meta = p / "meta.json"
    if p.is_dir() and meta.is_file():
        try:
            return str(json.loads(meta.read_text()).get("name", p.name))
        except (OSError, json.JSONDecodeError):
            pass
    return p.name if p.is_dir() else p.stem


def refresh_search_packs(store_root: Path) -> None:
    """Retrieval reads each embedder's search pack, which it rebuilds when stale: rebuild it
    here, once, in the driver, so that workers only read the store."""
    from ..retrieval.index import current_pack, enabled_embedders
    from ..store.bank import Bank

    bank = Bank.open(store_root)
    rows = bank.list()
    for e in enabled_embedders():
        current_pack(bank, e, rows)


class _StageReporter:
    """`zooctl.fit.run.Reporter` that passes each stage's name to the batch's progress."""

    def __init__(self, report) -> None:
        self.report = report

    def stage(self, name: str, total: int, done: int = 0) -> None:
        self.report(name)

    def step(self, terms: dict[str, float]) -> None:
        pass

    def message(self, text: str) -> None:
        pass


def fit_task(task: FitTask, report) -> dict[str, Any]:
    """Worker side: fit into a private folder; return the record and the files, as bytes."""
    from ..fit.config import FitConfig, preset
    from ..fit.job import fit_job
    from ..store.bank import Bank
    from ..store.fits import FitStore

    cfg = FitConfig.from_dict(task.config, preset(task.config.get("preset", "fast")))
    sweep_orphans()  # the folders of workers killed outright, here before
    # Named before it is made, so that a SIGTERM landing just after the folder appears still
    # reaches the `finally` that removes it.
    scratch, owner = scratch_path(task.name), None
    try:
        owner = claim(scratch)
        store = Path(task.store)
        source, src_root, video = task.source, store, None
        if task.ingest is not None:  # streamed into a store of its own: a few frames in memory
            from ..store.videos import VideoStore
            from ..video.ingest import add_video

            report("video")
            videos = VideoStore.open(scratch)
            summary = add_video(videos, Path(task.source), task.ingest)
            source, src_root = summary["name"], scratch
            video = {"name": summary["name"], "summary": summary, "file": videos.path(summary["name"])}
        private = FitStore(scratch)
        rec = fit_job(
            source,
            src_root,
            cfg,
            name=task.name,
            template=task.template,
            exclude=set(task.exclude) if task.exclude is not None else None,
            bank=Bank.open(store),
            outputs=task.outputs,
            out=scratch / "out",
            reporter=_StageReporter(report),
            cameras=task.cameras,
            fits=private,
        )
        report("sending")
        return {
            "record": rec,
            "fit_files": _read_tree(private.path(task.name)),
            "out_files": _read_tree(scratch / "out"),
            "scratch_out": str((scratch / "out").resolve()),
            # The compressed file (about a third of the arrays it holds), not the arrays.
            "video": None if video is None else {**video, "file": None, "data": video["file"].read_bytes()},
        }
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
        release(owner)


def _read_tree(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def commit_fit(item: BatchItem, value: dict[str, Any]) -> dict[str, Any]:
    """Driver side: store the video, write the outputs and the fit's store folder (record last)."""
    from ..store.fits import RECORD_VERSION, FitStore, rebase_paths
    from ..store.fs import store_lock, write_bytes_atomic, write_json_atomic

    task: FitTask = item.payload
    store = Path(task.store)
    fits = FitStore(store)
    video, planned, stored = value["video"], None, None
    if video is not None:
        from ..fit.job import store_preprocessed_video

        # A resumed batch may have stored it before it stopped, or another fit meanwhile: reused.
        planned = video["name"]
        stored = store_preprocessed_video(store, video, Path(task.source), task.masks)
    out = Path(task.out) if task.out is not None else fits.path(task.name).resolve()

    def as_stored(doc: dict[str, Any]) -> dict[str, Any]:  # the worker's paths and video name, as stored
        doc = rebase_paths(doc, value["scratch_out"], str(out))
        return _renamed_video(doc, planned, stored) if stored != planned else doc

    record = as_stored(value["record"])
    with store_lock(store):  # the outputs may be in the store (the fit's folder): all under the lock
        for rel, data in value["out_files"].items():
            if rel == "fit.json":
                data = json.dumps(as_stored(json.loads(data)), indent=2).encode()
            write_bytes_atomic(out / rel, data)
        for rel, data in value["fit_files"].items():
            if rel != "record.json":
                write_bytes_atomic(fits.path(task.name) / rel, data)
        write_json_atomic(fits.record_path(task.name), dict(record, schema_version=RECORD_VERSION))
    sent = sum(len(b) for b in value["out_files"].values()) + sum(len(b) for b in value["fit_files"].values())
    return fit_summary(record) | {"result_bytes": sent}


def fit_summary(record: dict[str, Any]) -> dict[str, Any]:
    m = record.get("metrics", {})
    return {
        "name": record.get("name"),
        "template": record.get("template"),
        "mask_iou": m.get("mask_iou"),
        "fit_s": record.get("timings", {}).get("total_wall"),
        "out": record.get("out"),
        "metrics": m,
        "retrieval": record.get("retrieval") or [],
    }


def skip_finished(item: BatchItem) -> dict[str, Any] | None:
    """``--resume``: a fit of this name that finished (its record says done) is not run again."""
    from ..store.fits import FitStore

    task: FitTask = item.payload
    fits = FitStore(Path(task.store))
    if not fits.exists(task.name):
        return None
    try:
        rec = fits.get(task.name)
    except ZooctlError:
        return None
    return fit_summary(rec) if rec.get("status") == "done" else None


def _renamed_video(record: dict[str, Any], old: str, new: str) -> dict[str, Any]:
    """``record`` naming the stored video ``new`` where the worker fitted it as ``old``, in its
    fields and in the commands its notes give (`close_trials_note`'s ``zooctl fit NAME ...``)."""
    said, says = f"`zooctl fit {shlex.quote(old)} ", f"`zooctl fit {shlex.quote(new)} "
    renamed = {k: new for k in ("source", "video", "stored_video") if record.get(k) == old}
    if isinstance(record.get("notes"), list):
        renamed["notes"] = [n.replace(said, says) if isinstance(n, str) else n for n in record["notes"]]
    return record | renamed
