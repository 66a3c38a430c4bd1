"""`video add` as a library call: decode, flow, segment, store; nothing is stored unless all succeed."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError, UsageError
from ..names import sanitize_name

# (stage, done, total): stages are "decode", "flow", "segment"
StageProgress = Callable[[str, int, int | None], None]


@dataclass
class AddOptions:
    """What `zooctl video add` accepts; see its --help for each field."""

    name: str | None = None
    masks: Path | None = None
    segmenter: str | None = None
    segmenter_options: dict[str, Any] = field(default_factory=dict)
    box: tuple[float, float, float, float] | None = None  # x, y, w, h in pixels of the original video
    box_frame: int = 0  # the stored frame the box is drawn on
    fps: float | None = None
    start: float | None = None
    end: float | None = None
    max_frames: int | None = None
    max_size: int | None = None  # None: the decoder's default (854); 0: keep the original size
    max_memory_gb: float | None = None  # None: the decoder's default budget (2 GB)
    flow: str = "dis"
    flow_options: dict[str, Any] = field(default_factory=dict)
    replace: bool = False
    lens: float | None = None  # 35 mm-equivalent focal length (mm); None: the one the file records


def _lens(path: Path, given: float | None) -> dict[str, Any] | None:
    """The lens stored with the video: the user's (``--lens``), else the one the file records."""
    from .lens import MAX_FOCAL_35MM, MIN_FOCAL_35MM, read_lens

    if given is None:
        return read_lens(path)
    if not MIN_FOCAL_35MM <= given <= MAX_FOCAL_35MM:
        raise UsageError(
            f"--lens {given:g} is not a 35 mm-equivalent focal length",
            hint=f"give millimetres between {MIN_FOCAL_35MM:g} and {MAX_FOCAL_35MM:g}, e.g. --lens 26 for a phone's main camera",
        )
    return {"focal_35mm": float(given), "lens_model": None, "from": "user"}


def parse_box(text: str) -> tuple[float, float, float, float]:
    """``"x,y,w,h"`` -> floats; UsageError for anything else."""
    parts = [p.strip() for p in text.split(",")]
    try:
        vals = tuple(float(p) for p in parts)
    except ValueError:
        vals = ()
    if len(vals) != 4 or vals[2] <= 0 or vals[3] <= 0:
        raise UsageError(
            f"--box {text!r} is not x,y,w,h", hint="give four numbers in pixels, e.g. --box 120,80,300,200"
        )
    return vals  # type: ignore[return-value]


def default_name(path: Path) -> str:
    p = Path(path)
    stem = p.name if p.is_dir() else p.stem
    if stem == "JPEGImages":
        stem = p.parent.name
    return sanitize_name(stem)


# The automatic segmenter when neither --segmenter nor masks are given: the one that wins on the
# shared real videos with its settings chosen leave-one-video-out (BENCHMARKS.md, Video store).
DEFAULT_SEGMENTER = "animalnet"

# The frame budget `video add` keeps when the user does not choose: a clip's own rate up to
# BUDGET_FRAMES frames; a longer one one frame in k (the least k that brings the rate to at most
# BUDGET_FPS) and its first BUDGET_SECONDS. 15 fps still samples a trot's stride (2-3 Hz) five
# times or more; 300 frames keep a fit to minutes on a CPU (its time grows with the frames).
BUDGET_FRAMES = 300
BUDGET_FPS = 15.0
BUDGET_SECONDS = 20.0
CHUNK = 8  # frames decoded, flowed and written at a time: what preprocessing holds at once
# Compressing and writing frames and flow runs on a thread of its own, beside the flow and the
# segmenter; at most this many chunks wait for it (their frames, float32 flow and occlusion).
WRITE_BEHIND_CHUNKS = 2


@dataclass
class FramePlan:
    """Which frames of a source `video add` keeps: its window, one frame in ``every``, and a
    note for the user when the budget (not the user) chose."""

    start: float | None
    end: float | None
    every: int = 1
    note: str | None = None


def plan_frames(path: Path, opts: AddOptions) -> FramePlan:
    """The frame budget: the user's --fps, --end or --max-frames choose; else a clip over
    ``BUDGET_FRAMES`` frames keeps one frame in k and its first ``BUDGET_SECONDS`` (see above)."""
    from .decode import probe

    if opts.fps is not None or opts.end is not None or opts.max_frames is not None:
        return FramePlan(opts.start, opts.end)
    info = probe(path)
    t0 = opts.start or 0.0
    span = None if info.duration is None else max(info.duration - t0, 0.0)
    if span is not None and round(span * info.fps) <= BUDGET_FRAMES:
        return FramePlan(opts.start, None)
    every = max(int(np.ceil(info.fps / BUDGET_FPS - 1e-9)), 1)
    rate = info.fps / every
    keep = min(BUDGET_SECONDS, BUDGET_FRAMES / rate)
    end = t0 + keep if span is None or span > keep + 0.5 / rate else None
    shown_end = t0 + (keep if end is not None else span)  # type: ignore[operator]
    of = f"a {t0 + span:.3g} s clip" if span is not None else "a clip of unknown length"
    note = (
        f"kept {t0:g}-{shown_end:.3g} s at {rate:.3g} fps of {of} at {info.fps:.3g} fps "
        f"(at most {BUDGET_FRAMES} frames by default); --start/--end/--fps to choose"
    )
    return FramePlan(opts.start, end, every, note)


def preprocess(path: str | Path, opts: AddOptions, progress: StageProgress | None = None):
    """Decode ``path`` and compute flow and masks; returns a `zooctl.store.videos.VideoRecord`
    (in memory: `add_video` streams into the store instead)."""
    import tempfile

    from ..store.videos import VideoWriter, read_video_h5

    path = Path(path).expanduser()
    name = opts.name or default_name(path)
    with tempfile.TemporaryDirectory(prefix="zooctl-video-") as tmp:
        file = Path(tmp) / f"{name}.h5"
        writers: list[VideoWriter] = []

        def begin(size: tuple[int, int], behind: int = 0) -> VideoWriter:
            writers.append(VideoWriter(file, size, behind))
            return writers[-1]

        try:
            ingest(path, AddOptions(**{**opts.__dict__, "name": name}), begin, progress)
            return read_video_h5(file)
        finally:
            for w in writers:  # its writer thread ends before the folder goes
                w.discard()


def add_video(
    store,
    path: str | Path,
    opts: AddOptions,
    progress: StageProgress | None = None,
    notify: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Preprocess ``path`` into ``store`` (a `VideoStore`); returns the index summary.

    Streams: frames, flow and masks go to a temporary file beside the video's final path as they
    are made (memory holds a few frames whatever the length), published under the store's lock
    once complete; any failure removes it and leaves the store as it was. ``notify`` is told what
    the frame budget kept, when it chose, and when automatic masks may hold no animal
    (`zooctl.video.animal_check`)."""
    name = opts.name or default_name(Path(path))
    store.check_new(name, opts.replace)  # fail before minutes of work
    opts = AddOptions(**{**opts.__dict__, "name": name})
    writers = []

    def begin(size: tuple[int, int], behind: int = 0):
        writers.append(store.begin_file(name, size, behind))
        return writers[-1]

    try:
        summary = ingest(Path(path), opts, begin, progress, notify)
        store.add_written(name, writers[0], summary, replace=opts.replace)
        return summary
    finally:
        for w in writers:  # gone once published; a failure on the way: removed
            w.discard()


def ingest(
    path: Path,
    opts: AddOptions,
    begin: Callable[[tuple[int, int], int], Any],
    progress: StageProgress | None = None,
    notify: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Decode, flow and segment ``path`` into the `zooctl.store.videos.VideoWriter` that
    ``begin((w, h), behind)`` makes (``behind``: the bytes that may wait for its writer thread), a
    few frames at a time; finishes it and returns its summary."""
    from ..plugins import get_registry
    from .decode import DEFAULT_MAX_MEMORY_GB, DEFAULT_MAX_SIZE, check_frame_memory, open_video

    path = Path(path).expanduser()
    name = opts.name or default_name(path)
    registry = get_registry()
    flow_spec = registry.get("flow_estimator", opts.flow)
    seg_name, seg_opts = _choose_segmenter(path, opts)
    seg_spec = registry.get("segmenter", seg_name)  # unknown names fail before decoding
    estimator = flow_spec.create(**opts.flow_options)

    def stage(label: str) -> Callable[[int, int | None], None] | None:
        return None if progress is None else (lambda done, total: progress(label, done, total))

    plan = plan_frames(path, opts)
    if plan.note and notify is not None:
        notify(plan.note)
    max_size = DEFAULT_MAX_SIZE if opts.max_size is None else (opts.max_size or None)
    stream = open_video(
        path,
        fps=opts.fps,
        start=plan.start,
        end=plan.end,
        max_frames=opts.max_frames,
        max_size=max_size,
        every=plan.every,
    )
    w, h = stream.size
    lens = _lens(path, opts.lens)
    check_frame_memory(
        w,
        h,
        CHUNK * (1 + WRITE_BEHIND_CHUNKS),  # the chunk at work and those waiting to be written
        DEFAULT_MAX_MEMORY_GB if opts.max_memory_gb is None else opts.max_memory_gb,
    )
    if seg_name == "masks":
        seg_opts.setdefault("source_indices", None)
        seg_opts.setdefault("original_size", stream.original_size)
        seg_opts.setdefault("source_frames", stream.source_frames)
        seg_opts.setdefault("source_exact", stream.kind != "file")
        seg_opts.setdefault("path", path)  # a DAVIS folder: MaskSegmenter reads its Annotations/
    segmenter = seg_spec.create(**seg_opts)
    uses_flow = getattr(segmenter, "uses_flow", False)
    flow_size = segmenter.flow_size(w, h) if uses_flow and hasattr(segmenter, "flow_size") else (w, h)
    writer = begin((w, h), WRITE_BEHIND_CHUNKS * CHUNK * w * h * (3 + 2 * 8 + 2))
    import inspect

    # a segmenter working at a smaller size gets the frames at that size too, made as they are
    # decoded (else it reads every frame back from the file to downscale it)
    takes_small = "working_frames" in inspect.signature(segmenter.segment).parameters
    seg_flow, small = _stream_frames(
        stream, writer, estimator, flow_size if uses_flow else None, stage, uses_flow and takes_small
    )
    try:
        t = len(writer)
        if t < 2:
            raise InputError(
                f"{path.name} gives only {t} frame"
                + (" in the chosen window" if opts.start or plan.end is not None else ""),
                hint="a video needs at least 2 frames (flow and tracking need motion); give a longer clip or window",
            )
        if seg_name == "masks":
            segmenter.source_indices = np.asarray(stream.source_indices, np.int64)
        box = scale_box(opts.box, stream.original_size, (w, h))
        kwargs: dict[str, Any] = {"box": box, "progress": stage("segment")}
        if uses_flow:
            kwargs["flow"] = seg_flow
        if small is not None:
            kwargs["working_frames"] = small
        if opts.box_frame:
            if box is None:
                raise UsageError("--box-frame places --box: give both", hint="--box x,y,w,h --box-frame N")
            if "box_frame" not in inspect.signature(segmenter.segment).parameters:
                raise UsageError(f"the {seg_name} segmenter takes its box on the first frame only")
            kwargs["box_frame"] = opts.box_frame
        from threadpoolctl import threadpool_limits

        # The segmenters' numpy networks multiply small matrices one frame at a time: a second BLAS
        # thread gains little and, on a busy machine, spins (BENCHMARKS.md, Video store).
        with threadpool_limits(1, user_api="blas"):
            masks = segmenter.segment(writer.frames, **kwargs)
        if not hasattr(masks, "shape"):
            masks = np.asarray(masks, dtype=bool)
        if tuple(masks.shape) != (t, h, w):
            raise InputError(
                f"segmenter {seg_name!r} returned masks of shape {tuple(masks.shape)}, expected {(t, h, w)}"
            )
        report = store_masks(masks, writer, seg_name, user=seg_name == "masks")
        from .animal_check import check_animal, is_checked, unsure_line

        if is_checked(seg_name, box):
            seg_report = dict(getattr(segmenter, "report", None) or {})
            # the masks as stored: a segmenter's lazy view would upsample its frames again
            report["animal_check"] = check_animal(writer.frames, writer.masks, {**seg_report, **report})
            line = unsure_line(report["animal_check"], name)
            if line and notify is not None:
                notify(line)
    finally:
        for part in (() if seg_flow is None else (seg_flow.forward, seg_flow.backward)) + (
            () if small is None else (small,)
        ):
            part.close()
    recorded = {
        k: str(Path(v).resolve()) if isinstance(v, Path) else str(v)
        for k, v in seg_opts.items()
        if k not in ("source_indices", "original_size", "source_frames", "source_exact")
    }
    return writer.finish(
        name,
        stream.fps,
        source={
            "path": str(stream.path),
            "kind": stream.kind,
            "sha256": stream.sha256,
            "fps": stream.source_fps,
            "original_width": stream.original_size[0],
            "original_height": stream.original_size[1],
            "start": plan.start,
            "end": plan.end,
            **({"every": plan.every} if plan.every > 1 else {}),
            **({"lens": lens} if lens is not None else {}),
        },
        source_indices=stream.source_indices,
        segmenter={
            "name": seg_name,
            "options": recorded,
            "box": list(box) if box is not None else None,
            "box_frame": opts.box_frame if box is not None else None,
            **report,
            **dict(getattr(segmenter, "report", None) or {}),
        },
        flow_estimator={"name": opts.flow, "options": {k: str(v) for k, v in opts.flow_options.items()}},
    )


def _stream_frames(stream, writer, estimator, flow_size, stage, keep_frames: bool = False):
    """Decode ``stream`` ``CHUNK`` frames at a time into ``writer``, with the flow of each frame
    pair. ``flow_size`` (w, h): also keep the float32 flow at that size for the segmenter (a
    `zooctl.video.flow.VideoFlow` of scratch arrays); None: it needs none. ``keep_frames``: and the
    frames at that size (INTER_AREA, a scratch array) when it is not theirs. -> (flow, frames)."""
    import cv2

    from .flow import VideoFlow, compute_video_flow, pair_occlusion, resize_flow
    from .scratch import ScratchArray

    decoded, flowed = stage("decode"), stage("flow")
    total = stream.total
    keep: VideoFlow | None = None
    small: ScratchArray | None = None
    prev: np.ndarray | None = None
    chunk: list[np.ndarray] = []

    def flush() -> None:
        nonlocal prev, keep, small
        frames = np.stack(chunk)
        chunk.clear()
        writer.add_frames(frames)
        if keep_frames and flow_size is not None and tuple(flow_size) != (frames.shape[2], frames.shape[1]):
            if small is None:
                small = ScratchArray(0, (flow_size[1], flow_size[0], 3), np.uint8)
            for f in frames:
                small.append(cv2.resize(f, tuple(flow_size), interpolation=cv2.INTER_AREA))
        pairs = frames if prev is None else np.concatenate([prev[None], frames])
        prev = frames[-1]
        if decoded:
            decoded(len(writer), total)
        if len(pairs) < 2:
            return
        # the occlusion check runs where the flow is written (behind: on the writer's thread)
        vf = compute_video_flow(estimator, pairs, occlusion=False)
        writer.add_flow(vf.forward, vf.backward, None, None, pair_occlusion)
        if flow_size is not None:
            if keep is None:  # grown as pairs arrive: the decoder's count is a header's estimate
                shape = (flow_size[1], flow_size[0], 2)
                keep = VideoFlow(
                    ScratchArray(0, shape, np.float32), ScratchArray(0, shape, np.float32), None, None
                )
            fw, fh = flow_size
            for f, b in zip(vf.forward, vf.backward):
                same = (fw, fh) == (f.shape[1], f.shape[0])
                keep.forward.append(f if same else resize_flow(f, fw, fh))
                keep.backward.append(b if same else resize_flow(b, fw, fh))
        if flowed:
            flowed(len(writer) - 1, None if total is None else max(total - 1, 1))

    for frame in stream:
        chunk.append(frame)
        if len(chunk) == CHUNK:
            flush()
    if chunk:
        flush()
    return keep, small


def store_masks(masks, writer, seg_name: str, user: bool) -> dict[str, Any]:
    """Check ``masks`` (T, H, W) bool, array-like) as `check_masks` does and store them with
    ``writer``, one frame at a time; returns what to report. A segmenter's masks are read once
    (a lazy view upsamples each frame when read): its specks are cleared frame by frame, as
    `check_coverage` clears them, and a video with no animal is refused once all are read."""
    if user:  # a user's specks may refuse the whole video before anything is stored
        cov = np.array([float(np.asarray(masks[i], bool).mean()) for i in range(len(masks))])
        clear, report = check_coverage(cov, seg_name, user)
        for i in range(len(masks)):
            m = np.asarray(masks[i], bool)
            writer.set_mask(i, np.zeros_like(m) if clear[i] else m)
        return report
    cov = np.zeros(len(masks))
    for i in range(len(masks)):
        m = np.asarray(masks[i], bool)
        cov[i] = float(m.mean())
        writer.set_mask(i, np.zeros_like(m) if 0 < cov[i] < MIN_COVERAGE else m)
    return check_coverage(cov, seg_name, user)[1]


MIN_COVERAGE = 0.001  # of the frame: below this a mask is a speck the fit cannot use


def check_masks(masks: np.ndarray, seg_name: str, user: bool) -> tuple[np.ndarray, dict[str, Any]]:
    """Masks (T, H, W) bool as a segmenter gave them -> the masks to store and what to report
    (`check_coverage`)."""
    t = len(masks)
    clear, report = check_coverage(masks.reshape(t, -1).mean(1), seg_name, user)
    if clear.any():
        masks = masks.copy()
        masks[clear] = False
    return masks, report


def check_coverage(cov: np.ndarray, seg_name: str, user: bool) -> tuple[np.ndarray, dict[str, Any]]:
    """Per-frame mask coverage (T,) -> which frames to clear (T,) bool and what to report.

    Frames without an animal are kept empty (the fit skips them) and listed. Specks under
    ``MIN_COVERAGE`` of the frame: an automatic segmenter's are cleared (noise), a user's are listed,
    and refused when most masked frames are specks. No animal in any frame is an InputError.
    """
    t = len(cov)
    cov = np.asarray(cov, np.float64)
    small = (cov > 0) & (cov < MIN_COVERAGE)
    if user and small.sum() > 0.5 * max(int((cov > 0).sum()), 1):
        raise InputError(
            f"the masks cover almost nothing: under {MIN_COVERAGE:.1%} of the frame in {int(small.sum())} "
            f"of {t} frames (median {np.median(cov[cov > 0]):.3%})",
            hint="the animal must be visible in the masks: check they belong to this video and are not inverted",
        )
    clear = np.zeros(t, bool)
    if not user and small.any():
        clear = small.copy()
        cov = np.where(clear, 0.0, cov)
        small = np.zeros(t, bool)
    empty = cov == 0
    if empty.all():
        raise InputError(
            f"the {seg_name} segmenter found no animal in any of the {t} frames; nothing was stored",
            hint="give --box x,y,w,h around the animal (and --box-frame N), or your own --masks",
        )
    report: dict[str, Any] = {"empty_frames": np.flatnonzero(empty).tolist()}
    if small.any():
        report["small_frames"] = np.flatnonzero(small).tolist()
    return clear, report


def _choose_segmenter(path: Path, opts: AddOptions) -> tuple[str, dict[str, Any]]:
    seg_opts = dict(opts.segmenter_options)
    if opts.masks is not None:
        if opts.segmenter not in (None, "masks"):
            raise UsageError(
                f"--masks and --segmenter {opts.segmenter} disagree",
                hint="--masks uses your masks; drop one of the two",
            )
        seg_opts["path"] = opts.masks
        return "masks", seg_opts
    has_annotations = path.is_dir() and (path / "Annotations").is_dir()
    if opts.segmenter is None:
        return ("masks" if has_annotations else DEFAULT_SEGMENTER), seg_opts
    if opts.segmenter == "masks" and not has_annotations:
        raise UsageError(
            "the masks segmenter needs masks", hint="pass --masks DIR|VIDEO (or a folder with Annotations/)"
        )
    return opts.segmenter, seg_opts


def scale_box(box, original: tuple[int, int], stored: tuple[int, int]) -> tuple[int, int, int, int] | None:
    if box is None:
        return None
    sx, sy = stored[0] / original[0], stored[1] / original[1]
    x, y, bw, bh = box
    return round(x * sx), round(y * sy), max(round(bw * sx), 1), max(round(bh * sy), 1)
