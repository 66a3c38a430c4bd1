"""`zooctl video ...`: preprocessed videos (frames, masks, optical flow) in the store."""

from __future__ import annotations

from pathlib import Path

import typer

from . import _common
from ._common import (
    APP_OPTS,
    JsonOpt,
    console,
    err_console,
    print_json,
    print_listing,
    print_table,
    stage_progress,
    store_root,
)

app = typer.Typer(
    **APP_OPTS,
    help="Turn videos into frames, masks and optical flow, stored once for every fit.",
    no_args_is_help=True,
)


def _store():
    from ..store.videos import VideoStore

    return VideoStore.open(store_root())


def _parse_options(items: list[str] | None, flag: str) -> dict[str, object]:
    """``KEY=VALUE`` strings -> dict, values parsed as int, float, bool when they look like one."""
    from ..errors import UsageError

    out: dict[str, object] = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise UsageError(f"{flag} {item!r} is not KEY=VALUE", hint=f"e.g. {flag} iterations=3")
        v: object = value
        for conv in (int, float):
            try:
                v = conv(value)
                break
            except ValueError:
                pass
        if value.lower() in ("true", "false"):
            v = value.lower() == "true"
        out[key.strip()] = v
    return out


@app.command("add")
def add(
    path: Path = typer.Argument(
        ...,
        help="A video (.mp4 .mov .avi .mkv .webm), a folder of images, or a folder with JPEGImages/ (and Annotations/).",
    ),
    name: str = typer.Option(None, "--name", help="Video name (default: the file or folder name)."),
    masks: Path = typer.Option(
        None, "--masks", help="Your masks: a folder of mask images or a mask video, one per frame."
    ),
    segmenter: str = typer.Option(
        None,
        "--segmenter",
        help="masks | animalnet | grabcut | selftrain | onnx | a plugin's (default: masks when given, else animalnet).",
    ),
    box: str = typer.Option(
        None,
        "--box",
        help="x,y,w,h around the animal in frame --box-frame (original pixels): a hint that chooses which "
        "animal (the localiser then seeds it; the box's own pixels where it sees no animal there). Default: "
        "the localiser finds the animal (ImageNet animal classes and motion).",
    ),
    box_frame: int = typer.Option(
        0, "--box-frame", help="The frame --box is drawn on (a stored frame number; default 0)."
    ),
    model: Path = typer.Option(None, "--model", help="Local .onnx model for --segmenter onnx."),
    seg_option: list[str] = typer.Option(
        None, "--seg-option", help="KEY=VALUE option for the segmenter (repeatable)."
    ),
    flow: str = typer.Option("dis", "--flow", help="Flow estimator."),
    flow_preset: str = typer.Option(
        None,
        "--flow-preset",
        help="DIS preset: ultrafast | fast | medium (default medium). The automatic masks follow the flow: "
        "ultrafast is quicker but segments worse (BENCHMARKS.md, Current figures: automatic masks).",
    ),
    flow_size: int = typer.Option(
        None,
        "--flow-size",
        help="Longest side DIS flow is computed at (the stored flow is upsampled to the frames; default 640; 0: full "
        "size). A smaller size is quicker but the automatic masks, which follow the flow, are worse.",
    ),
    fps: float = typer.Option(
        None,
        "--fps",
        help="Resample a video file to this rate; for image folders, their rate (default 30). Default: the "
        "source's rate up to 300 frames; a longer clip keeps at most 15 fps and its first 20 s.",
    ),
    start: float = typer.Option(None, "--start", help="First second to keep."),
    end: float = typer.Option(None, "--end", help="Second to stop at (default: see --fps)."),
    max_frames: int = typer.Option(None, "--max-frames", help="Keep at most this many frames."),
    max_size: int = typer.Option(
        854, "--max-size", help="Downscale so the longest side is at most this many pixels (0: keep)."
    ),
    max_memory: float = typer.Option(
        2.0,
        "--max-memory",
        help="Refuse frames so large that preprocessing would need more than this many GB (about 32 bytes per "
        "stored pixel, a few frames at a time: the video's length does not count).",
    ),
    lens: float = typer.Option(
        None,
        "--lens",
        help="The lens as a 35 mm-equivalent focal length in mm (a phone's main camera: about 26), stored "
        "with the video for its fits. Default: the one the file records (iPhone QuickTime metadata, or a "
        "frame folder's Exif), else none (its fits then assume a normal lens, 43 mm).",
    ),
    replace: bool = typer.Option(False, "--replace", help="Overwrite a video of the same name."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bars."),
    json_out: bool = JsonOpt,
) -> None:
    """Decode a video, compute forward/backward flow and masks, and store them (atomic: a failure stores nothing).

    Automatic masks (no --box) are checked: a warning says when they may hold no animal."""
    from ..video.ingest import AddOptions, add_video, parse_box

    seg_opts = _parse_options(seg_option, "--seg-option")
    if model is not None:
        seg_opts["model"] = model
        segmenter = segmenter or "onnx"
    flow_opts = _parse_options(None, "--flow-option")
    if flow_preset:
        flow_opts["preset"] = flow_preset
    if flow_size is not None:
        flow_opts["max_size"] = flow_size
    opts = AddOptions(
        name=name,
        masks=masks,
        segmenter=segmenter,
        segmenter_options=seg_opts,
        box=parse_box(box) if box else None,
        box_frame=box_frame,
        fps=fps,
        start=start,
        end=end,
        max_frames=max_frames,
        max_size=max_size,
        max_memory_gb=max_memory,
        flow=flow,
        flow_options=flow_opts,
        replace=replace,
        lens=lens,
    )

    warnings: list[str] = []  # said after the summary line, not between the progress bars

    def notify(text: str) -> None:
        if json_out:
            return
        if text.startswith("warning:"):
            warnings.append(text)
        else:
            err_console.print(text, highlight=False, markup=False)

    with stage_progress(not quiet and not json_out) as progress:
        summary = add_video(_store(), path, opts, progress=progress, notify=notify)
    if json_out:
        print_json(summary)
    else:
        console.print(
            f"added [bold]{summary['name']}[/]: {summary['frames']} frames {summary['width']}x{summary['height']} at {summary['fps']:g} fps, "
            f"masks by {summary['segmenter']} (mean coverage {summary['mask_coverage_mean']:.1%})",
            highlight=False,
        )
        if summary.get("empty_masks"):
            console.print(
                f"{summary['empty_masks']} of {summary['frames']} frames have no animal in their mask "
                f"(stored empty; the fit skips them): see `zooctl video show {summary['name']}`",
                style="yellow",
                highlight=False,
                markup=False,
            )
        for text in warnings:
            err_console.print(text, style="yellow", highlight=False, markup=False)


@app.command("list")
def list_(json_out: bool = JsonOpt) -> None:
    """List the stored videos."""
    rows = _store().list()

    def cells(r: dict) -> list[str]:
        return [
            r["name"],
            str(r["frames"]),
            f"{r['width']}x{r['height']}",
            f"{r['fps']:g}",
            f"{r['mask_coverage_mean']:.1%}",
            r["segmenter"],
            r["source"]["kind"],
        ]

    cols = [
        ("name", "left"),
        ("frames", "right"),
        ("size", "right"),
        ("fps", "right"),
        ("coverage", "right"),
        ("masks", "left"),
        ("source", "left"),
    ]
    print_listing(rows, json_out, cols, cells, title=f"{len(rows)} videos")


def _read_stats(store, name: str, stats) -> dict:
    """``stats(h5py.File)`` of a stored video; a damaged file is one clear error."""
    from ..store.h5 import read_h5

    store.summary(name)  # an unknown name: NotFoundError
    return read_h5(
        store.path(name),
        "the video file",
        "remove it with `zooctl video rm` and add it again",
        stats,
        ["boxes"],  # what it reads whole; the rest a frame at a time
    )


@app.command("show")
def show(
    name: str = typer.Argument(..., help="Video name."),
    preview: Path = typer.Option(
        None, "--preview", help="Write an H.264 .mp4: frames with mask outline | flow colours."
    ),
    json_out: bool = JsonOpt,
) -> None:
    """Show a stored video: frames, fps, size, mask coverage per frame, flow statistics."""
    from ..video.lens import lens_line
    from ..video.stats import seeding_lines, stored_video_stats

    store = _store()
    info = {**store.summary(name), **_read_stats(store, name, stored_video_stats)}
    seeding = info.get("seeding")
    need_check = bool(seeding) and "animal_check" not in seeding  # stored before the check
    if need_check or preview:
        from ..store.video_reader import StoredVideo

        with StoredVideo(store.path(name)) as rec:
            if need_check:
                from ..video.animal_check import stored_animal_check

                check = stored_animal_check(rec)  # made now, not stored
                if check is not None:
                    seeding["animal_check"] = check
            if preview:
                from ..video.preview import write_preview

                with stage_progress(not json_out) as progress:
                    write_preview(
                        rec,
                        preview,
                        progress=None if progress is None else (lambda d, t: progress("preview", d, t)),
                    )
                info["preview"] = str(preview)
    if json_out:
        print_json(info)
        return
    src = info["source"]
    console.print(
        f"[bold]{info['name']}[/]  {info['frames']} frames, {info['width']}x{info['height']}, {info['fps']:g} fps ({info['duration_s']:g} s)",
        highlight=False,
    )
    console.print(
        f"source: {src['kind']} {src['path']}  sha256 {src['sha256'][:12]}", highlight=False, markup=False
    )
    if src.get("lens"):
        console.print(lens_line(src["lens"]), highlight=False, markup=False)
    console.print(
        f"masks: {info['segmenter']}; flow: {info['flow_estimator']}", highlight=False, markup=False
    )
    for line in seeding_lines(info.get("seeding")):
        console.print(line, highlight=False, markup=False)
    fs = info["flow"]
    console.print(
        f"flow: mean {fs['mean_magnitude']:.2f} px, p99 {fs['p99_magnitude']:.2f} px, max {fs['max_magnitude']:.1f} px; "
        f"occluded {fs['occluded_fraction']:.1%} (forward-backward check)",
        highlight=False,
    )
    cov = info["mask_coverage"]
    how = (info.get("seeding") or {}).get("seeding") or [""] * len(cov)
    rows = [
        [str(i), f"{c:.1%}", " ".join(str(v) for v in b), s]
        for i, (c, b, s) in enumerate(zip(cov, info["boxes"], how))
    ]
    print_table([("frame", "right"), ("coverage", "right"), ("box x y w h", "left"), ("mask", "left")], rows)
    if preview:
        console.print(f"preview written to {preview}", highlight=False, markup=False)


_common.add_rm_command(app, _store, "Remove stored videos.", "Video names to remove.")


@app.command("export")
def export(
    name: str = typer.Argument(..., help="Video name."),
    what: str = typer.Option("frames", "--what", help="frames | masks | flow"),
    out: Path = typer.Option(..., "-o", "--out", help="Folder to write into (created)."),
    json_out: bool = JsonOpt,
) -> None:
    """Export frames (JPEG), masks (PNG) or flow (.npy per direction and occlusion PNGs) to a folder."""
    from ..video.folder_export import export_video

    written = export_video(_store(), name, what, out)
    if json_out:
        print_json({"name": name, "what": what, "out": str(out), "files": written})
    else:
        console.print(f"wrote {written} files to {out}", highlight=False, markup=False)


_common.add_upkeep_commands(
    app,
    _store,
    "videos",
    clean_help="""Remove leftovers of killed writers (temporary files, caches of removed videos).

Never deletes a video file: ones the index does not name are listed (`zooctl video repair`
indexes the valid ones).""",
    repair_help="""Rebuild the video index from the video files (after it was lost or damaged).

Every valid video file is indexed; invalid ones are listed with the reason and left in place.""",
)
