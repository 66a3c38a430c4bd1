"""Turn a video file, a folder of images or a DAVIS-style folder into an RGB frame array.

Video files are decoded by the ffmpeg binary that ``imageio-ffmpeg`` ships (it honours phone
rotation metadata); frame-rate resampling, the time window and downscaling are done by ffmpeg's
own filters so a 4K clip never exists in memory at full size.
"""

from __future__ import annotations

import hashlib
import logging
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError, UsageError

VIDEO_SUFFIXES = (".mp4", ".mov", ".avi", ".mkv", ".webm", ".m4v")
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp")
DEFAULT_MAX_SIZE = 854  # longest side in pixels: DAVIS 480p; keeps flow and GrabCut affordable on a CPU
DEFAULT_FOLDER_FPS = 30.0
# Preprocessing holds, per stored pixel: RGB (3 B), forward and backward flow (16 B), occlusion and
# mask bytes, grey copies and the segmenter's working images: about 32 bytes. The default budget
# keeps `video add` under 2 GB however small the input file (a tiny file can hold hours of video).
BYTES_PER_PIXEL = 32
DEFAULT_MAX_MEMORY_GB = 2.0

ProgressFn = Callable[[int, int | None], None]  # (frames done, total or None)


@dataclass
class DecodedVideo:
    """Decoded frames and where they came from.

    ``frames``: (T, H, W, 3) uint8 RGB at the stored size. ``source_indices``: (T,) int, the index of each
    kept frame in the source sequence (a folder's sorted images; for a file, the frame number at the
    source rate), used to match user-supplied masks. ``annotations``: a DAVIS ``Annotations/`` folder.
    """

    frames: np.ndarray
    fps: float
    kind: str  # "file" | "images" | "davis"
    path: Path
    sha256: str
    original_size: tuple[int, int]  # (width, height) before downscaling
    source_fps: float
    source_indices: np.ndarray
    annotations: Path | None = None
    image_files: list[Path] = field(default_factory=list)
    source_frames: int | None = None  # frames in the whole source (a file's from its header: approximate)


def image_files(folder: Path) -> list[Path]:
    """The images of a folder in natural order (``2.png`` before ``10.png``)."""
    files = [
        p
        for p in folder.iterdir()
        if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES and not p.name.startswith(".")
    ]
    return sorted(files, key=_natural_key)


def _natural_key(p: Path) -> list[object]:
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", p.name)]


def scaled_size(width: int, height: int, max_size: int | None) -> tuple[int, int]:
    """(w, h) with the longest side at most ``max_size``, aspect kept, both even (H.264 needs it)."""
    if max_size is not None and max_size < 16:
        raise UsageError(f"--max-size {max_size} is too small", hint="use at least 16 pixels (default 854)")
    s = 1.0 if not max_size or max(width, height) <= max_size else max_size / max(width, height)
    w, h = round(width * s), round(height * s)
    if s != 1.0:
        w, h = w - w % 2, h - h % 2
    return max(w, 2), max(h, 2)


def decode(
    path: str | Path,
    fps: float | None = None,
    start: float | None = None,
    end: float | None = None,
    max_frames: int | None = None,
    max_size: int | None = DEFAULT_MAX_SIZE,
    progress: ProgressFn | None = None,
    max_memory_gb: float | None = DEFAULT_MAX_MEMORY_GB,
) -> DecodedVideo:
    """Decode ``path`` (video file, image folder, folder with ``JPEGImages/``, or one image: a
    one-frame video).

    ``fps`` resamples a video file; for a folder it declares the images' rate (default 30).
    ``start``/``end`` are seconds; ``max_frames`` keeps the first N after those; ``max_size`` bounds
    the longest side (0 or None: keep the original size). ``max_memory_gb`` bounds what
    preprocessing the decoded frames will take (``BYTES_PER_PIXEL`` per stored pixel); a video
    over it is refused before (or while) decoding, with a hint (None: no bound).
    """
    path = Path(path).expanduser()
    if not path.exists():
        raise InputError(
            f"{path} does not exist",
            hint="give a video file (.mp4 .mov .avi .mkv .webm) or a folder of images",
        )
    if fps is not None and not (0 < fps <= 1000):
        raise UsageError(f"--fps {fps} is not a frame rate", hint="give a positive number such as 30")
    if start is not None and start < 0:
        raise UsageError(f"--start {start} is negative", hint="times are seconds from the start of the video")
    if start is not None and end is not None and end <= start:
        raise UsageError(f"--end {end} is not after --start {start}", hint="give a window with end > start")
    if max_frames is not None and max_frames < 1:
        raise UsageError(f"--max-frames {max_frames} must be at least 1")
    if max_memory_gb is not None and not max_memory_gb > 0:
        raise UsageError(f"--max-memory {max_memory_gb} must be positive", hint="give gigabytes, e.g. 4")
    budget = _Budget(max_memory_gb)
    if path.is_dir() or path.suffix.lower() in IMAGE_SUFFIXES:
        return _decode_folder(path, fps, start, end, max_frames, max_size, progress, budget)
    if path.suffix.lower() not in VIDEO_SUFFIXES:
        raise InputError(
            f"{path.name}: not a video file zooctl reads ({path.suffix or 'no suffix'})",
            hint=f"use one of {' '.join(VIDEO_SUFFIXES)}, an image, or a folder of images",
        )
    return _decode_file(path, fps, start, end, max_frames, max_size, progress, budget)


class _Budget:
    """Refuses a video whose frames would need more than ``gb`` of preprocessing memory."""

    def __init__(self, gb: float | None) -> None:
        self.gb = gb

    def check(self, frames: int, w: int, h: int, estimate: bool = False) -> None:
        if self.gb is None:
            return
        need = frames * w * h * BYTES_PER_PIXEL / 1e9
        if need > self.gb:
            what = f"{'about ' if estimate else 'over '}{frames} frames of {w}x{h}"
            raise InputError(
                f"{what} need about {need:.1f} GB to preprocess, over the --max-memory limit of {self.gb:g} GB",
                hint="keep fewer frames (--max-frames, --fps, --start/--end), a smaller --max-size, "
                "or raise --max-memory",
            )


# -- folders --------------------------------------------------------------------------------------


def _decode_folder(folder, fps, start, end, max_frames, max_size, progress, budget) -> DecodedVideo:
    from PIL import Image

    from .images import open_image

    kind, annotations, img_dir = "images", None, folder
    if folder.is_file():  # one photo: the folder of that one image
        img_dir = folder.parent
        files = [folder]
    else:
        if (folder / "JPEGImages").is_dir():
            kind, img_dir = "davis", folder / "JPEGImages"
            ann = folder / "Annotations"
            annotations = ann if ann.is_dir() and image_files(ann) else None
        files = image_files(img_dir)
    if not files:
        raise InputError(
            f"{img_dir} holds no images",
            hint=f"a frame folder needs files with one of {' '.join(IMAGE_SUFFIXES)} (or a JPEGImages/ subfolder)",
        )
    rate = float(fps) if fps else DEFAULT_FOLDER_FPS
    first = int(np.ceil((start or 0.0) * rate - 1e-9))
    last = len(files) if end is None else min(len(files), int(np.ceil(end * rate - 1e-9)))
    indices = np.arange(first, last)
    if max_frames is not None:
        indices = indices[:max_frames]
    if indices.size == 0:
        raise InputError(
            f"no frames of {folder} fall in the window --start {start} --end {end}",
            hint=f"it has {len(files)} images at {rate:g} fps",
        )
    digest = hashlib.sha256()
    frames: list[np.ndarray] = []
    orig: tuple[int, int] | None = None
    size: tuple[int, int] | None = None
    for n, i in enumerate(indices):
        f = files[i]
        data = f.read_bytes()
        digest.update(f.name.encode() + b"\0" + data)
        try:
            with open_image(f) as im:
                im.load()
                rgb = im.convert("RGB")
        except InputError:
            raise
        except Exception as exc:
            raise InputError(
                f"{f} is not a readable image: {exc}", hint="remove or replace that file"
            ) from None
        if orig is None:
            orig = rgb.size
            size = scaled_size(*orig, max_size)
            budget.check(len(indices), *size)
        elif rgb.size != orig:
            raise InputError(
                f"{f.name} is {rgb.size[0]}x{rgb.size[1]}, the first image is {orig[0]}x{orig[1]}",
                hint="every frame of a video must have the same size",
            )
        if rgb.size != size:
            rgb = rgb.resize(size, Image.Resampling.BOX if size[0] < orig[0] else Image.Resampling.BICUBIC)
        frames.append(np.asarray(rgb, dtype=np.uint8))
        if progress:
            progress(n + 1, len(indices))
    assert orig is not None
    return DecodedVideo(
        frames=np.stack(frames),
        fps=rate,
        kind=kind,
        path=folder.resolve(),
        sha256=digest.hexdigest(),
        original_size=orig,
        source_fps=rate,
        source_indices=indices.astype(np.int64),
        annotations=annotations,
        image_files=[files[i] for i in indices],
        source_frames=len(files),
    )


# -- video files ----------------------------------------------------------------------------------


def file_sha256(path: Path, chunk: int = 1 << 20) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()


def _probe(path: Path) -> tuple[tuple[int, int], float, float | None]:
    """(source (w, h) after rotation, fps, duration s) from ffmpeg's header; InputError when unreadable."""
    import imageio_ffmpeg

    gen = imageio_ffmpeg.read_frames(str(path), pix_fmt="rgb24")
    try:
        meta = next(gen)
    except (RuntimeError, OSError, StopIteration) as exc:
        raise InputError(
            f"{path.name} is not a readable video: {_short(exc)}",
            hint="check that the file is complete and plays in a video player",
        ) from None
    finally:
        gen.close()
    w, h = meta["size"]
    fps = float(meta.get("fps") or 0.0)
    dur = meta.get("duration")
    return (int(w), int(h)), fps, float(dur) if dur else None


def _short(exc: BaseException) -> str:
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    useful = [
        ln
        for ln in lines
        if "Invalid data" in ln or "moov atom" in ln or "No such file" in ln or "does not contain" in ln
    ]
    return (useful or lines or [type(exc).__name__])[-1][:200]


def _decode_file(path, fps, start, end, max_frames, max_size, progress, budget) -> DecodedVideo:
    import imageio_ffmpeg

    if path.stat().st_size == 0:
        raise InputError(f"{path.name} is empty (0 bytes)", hint="re-export or re-copy the video")
    (ow, oh), src_fps, duration = _probe(path)
    if src_fps <= 0:
        src_fps = DEFAULT_FOLDER_FPS
    w, h = scaled_size(ow, oh, max_size)
    rate = float(fps) if fps else src_fps
    filters = []
    if fps:
        filters.append(f"fps={rate:.6f}")
    if (w, h) != (ow, oh):
        filters.append(f"scale={w}:{h}:flags=area")
    input_params = ["-ss", f"{start:.6f}"] if start else []
    output_params = []
    if end is not None:
        output_params += ["-t", f"{end - (start or 0.0):.6f}"]
    if filters:
        output_params += ["-vf", ",".join(filters)]
    if max_frames is not None:
        output_params += ["-frames:v", str(int(max_frames))]
    total = None
    if duration:
        span = (min(end, duration) if end is not None else duration) - (start or 0.0)
        total = max(int(round(span * rate)), 0)
        if max_frames is not None:
            total = min(total, max_frames)
        budget.check(total, w, h, estimate=True)
    frames: list[np.ndarray] = []
    # imageio-ffmpeg logs a warning whenever the output size differs from the source: that is our scaling
    logging.getLogger("imageio_ffmpeg").setLevel(logging.ERROR)
    gen = imageio_ffmpeg.read_frames(
        str(path), pix_fmt="rgb24", input_params=input_params, output_params=output_params
    )
    try:
        meta = next(gen)
        fw, fh = meta["size"]
        for buf in gen:
            frames.append(np.frombuffer(buf, dtype=np.uint8).reshape(fh, fw, 3))
            budget.check(len(frames), fw, fh)  # the header's duration may be missing or lie
            if progress:
                progress(len(frames), total)
    except (RuntimeError, OSError) as exc:
        if not frames:
            raise InputError(
                f"{path.name} could not be decoded: {_short(exc)}",
                hint="check that the file is complete and plays in a video player",
            ) from None
        # a truncated file: keep the frames that decoded, as players do
    finally:
        gen.close()
    if not frames:
        window = f" in the window --start {start} --end {end}" if start or end is not None else ""
        raise InputError(
            f"{path.name} has no video frames{window}", hint="check the file and the time window"
        )
    t0 = start or 0.0
    indices = np.round((t0 + np.arange(len(frames)) / rate) * src_fps).astype(np.int64)
    return DecodedVideo(
        frames=np.stack(frames),
        fps=rate,
        kind="file",
        path=path.resolve(),
        sha256=file_sha256(path),
        original_size=(ow, oh),
        source_fps=src_fps,
        source_indices=indices,
        source_frames=int(round(duration * src_fps)) if duration else None,
    )
