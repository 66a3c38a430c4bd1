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


def preprocess(
    path: str | Path,
    opts: AddOptions,
    progress: StageProgress | None = None,
    on_flow: Callable[[np.ndarray, Any], None] | None = None,
):
    """Decode ``path`` and compute flow and masks; returns a `zooctl.store.videos.VideoRecord`.

    ``on_flow(frames, flow)``: called once the frames and flow (a `zooctl.video.flow.VideoFlow`) are
    final, before segmentation (`add_video` starts writing them to the store there)."""
    from ..plugins import get_registry
    from ..store.videos import VideoRecord
    from .decode import DEFAULT_MAX_MEMORY_GB, DEFAULT_MAX_SIZE, decode
    from .flow import compute_video_flow

    path = Path(path).expanduser()
    name = opts.name or default_name(path)
    registry = get_registry()
    flow_spec = registry.get("flow_estimator", opts.flow)
    seg_name, seg_opts = _choose_segmenter(path, opts)
    seg_spec = registry.get("segmenter", seg_name)  # unknown names fail before decoding

    def stage(label: str) -> Callable[[int, int | None], None] | None:
        return None if progress is None else (lambda done, total: progress(label, done, total))

    max_size = DEFAULT_MAX_SIZE if opts.max_size is None else (opts.max_size or None)
    dv = decode(
        path,
        fps=opts.fps,
        start=opts.start,
        end=opts.end,
        max_frames=opts.max_frames,
        max_size=max_size,
        progress=stage("decode"),
        max_memory_gb=DEFAULT_MAX_MEMORY_GB if opts.max_memory_gb is None else opts.max_memory_gb,
    )
    t, h, w = dv.frames.shape[:3]
    if t < 2:
        raise InputError(
            f"{path.name} gives only {t} frame"
            + (" in the chosen window" if opts.start or opts.end is not None else ""),
            hint="a video needs at least 2 frames (flow and tracking need motion); give a longer clip or window",
        )
    estimator = flow_spec.create(**opts.flow_options)
    vf = compute_video_flow(estimator, dv.frames, progress=stage("flow"))
    if on_flow is not None:
        on_flow(dv.frames, vf)

    if seg_name == "masks":
        seg_opts.setdefault("source_indices", dv.source_indices)
        seg_opts.setdefault("original_size", dv.original_size)
        seg_opts.setdefault("source_frames", dv.source_frames)
        seg_opts.setdefault("source_exact", dv.kind != "file")
        seg_opts.setdefault("path", path)  # a DAVIS folder: MaskSegmenter reads its Annotations/
    segmenter = seg_spec.create(**seg_opts)
    box = _scale_box(opts.box, dv.original_size, (w, h))
    kwargs: dict[str, Any] = {"box": box, "progress": stage("segment")}
    if getattr(segmenter, "uses_flow", False):
        kwargs["flow"] = vf
    if opts.box_frame:
        import inspect

        if box is None:
            raise UsageError("--box-frame places --box: give both", hint="--box x,y,w,h --box-frame N")
        if "box_frame" not in inspect.signature(segmenter.segment).parameters:
            raise UsageError(f"the {seg_name} segmenter takes its box on the first frame only")
        kwargs["box_frame"] = opts.box_frame
    masks = np.asarray(segmenter.segment(dv.frames, **kwargs), dtype=bool)
    if masks.shape != (t, h, w):
        raise InputError(
            f"segmenter {seg_name!r} returned masks of shape {masks.shape}, expected {(t, h, w)}"
        )

    masks, report = check_masks(masks, seg_name, user=seg_name == "masks")
    recorded = {
        k: str(Path(v).resolve()) if isinstance(v, Path) else str(v)
        for k, v in seg_opts.items()
        if k not in ("source_indices", "original_size", "source_frames", "source_exact")
    }
    return VideoRecord(
        name=name,
        frames=dv.frames,
        masks=masks,
        flow_forward=vf.forward,
        flow_backward=vf.backward,
        occlusion_forward=vf.occlusion_forward,
        occlusion_backward=vf.occlusion_backward,
        fps=dv.fps,
        source={
            "path": str(dv.path),
            "kind": dv.kind,
            "sha256": dv.sha256,
            "fps": dv.source_fps,
            "original_width": dv.original_size[0],
            "original_height": dv.original_size[1],
            "start": opts.start,
            "end": opts.end,
        },
        source_indices=dv.source_indices,
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


MIN_COVERAGE = 0.001  # of the frame: below this a mask is a speck the fit cannot use


def check_masks(masks: np.ndarray, seg_name: str, user: bool) -> tuple[np.ndarray, dict[str, Any]]:
    """Masks (T, H, W) bool as a segmenter gave them -> the masks to store and what to report.

    Frames without an animal are kept empty (the fit skips them) and listed. Specks under
    ``MIN_COVERAGE`` of the frame: an automatic segmenter's are cleared (noise), a user's are listed,
    and refused when most masked frames are specks. No animal in any frame is an InputError.
    """
    t = len(masks)
    cov = masks.reshape(t, -1).mean(1)
    small = (cov > 0) & (cov < MIN_COVERAGE)
    if user and small.sum() > 0.5 * max(int((cov > 0).sum()), 1):
        raise InputError(
            f"the masks cover almost nothing: under {MIN_COVERAGE:.1%} of the frame in {int(small.sum())} "
            f"of {t} frames (median {np.median(cov[cov > 0]):.3%})",
            hint="the animal must be visible in the masks: check they belong to this video and are not inverted",
        )
    if not user and small.any():
        masks = masks.copy()
        masks[small] = False
        small[:] = False
    empty = ~masks.reshape(t, -1).any(1)
    if empty.all():
        raise InputError(
            f"the {seg_name} segmenter found no animal in any of the {t} frames; nothing was stored",
            hint="give --box x,y,w,h around the animal (and --box-frame N), or your own --masks",
        )
    report = {"empty_frames": np.flatnonzero(empty).tolist()}
    if small.any():
        report["small_frames"] = np.flatnonzero(small).tolist()
    return masks, report


def add_video(
    store, path: str | Path, opts: AddOptions, progress: StageProgress | None = None
) -> dict[str, Any]:
    """Preprocess ``path`` and add it to ``store`` (a `VideoStore`); returns the index summary.

    The store file's frames and flow are written on a background thread while the masks are made."""
    name = opts.name or default_name(Path(path))
    store.check_new(name, opts.replace)  # fail before minutes of work
    images = []

    def begin(frames: np.ndarray, vf: Any) -> None:
        images.append(
            store.begin_image(frames, vf.forward, vf.backward, vf.occlusion_forward, vf.occlusion_backward)
        )

    try:
        rec = preprocess(path, AddOptions(**{**opts.__dict__, "name": name}), progress, on_flow=begin)
        return store.add(rec, replace=opts.replace, image=images[0] if images else None)
    finally:
        for image in images:  # a failure on the way: stop the background write
            image.close()


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
        return ("masks" if has_annotations else "grabcut"), seg_opts
    if opts.segmenter == "masks" and not has_annotations:
        raise UsageError(
            "the masks segmenter needs masks", hint="pass --masks DIR|VIDEO (or a folder with Annotations/)"
        )
    return opts.segmenter, seg_opts


def _scale_box(box, original: tuple[int, int], stored: tuple[int, int]) -> tuple[int, int, int, int] | None:
    if box is None:
        return None
    sx, sy = stored[0] / original[0], stored[1] / original[1]
    x, y, bw, bh = box
    return round(x * sx), round(y * sy), max(round(bw * sx), 1), max(round(bh * sy), 1)
