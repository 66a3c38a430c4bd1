"""Turn a video file, a folder of images or a DAVIS-style folder into an RGB frame array.

Video files are decoded by the ffmpeg binary that ``imageio-ffmpeg`` ships (it honours phone
rotation metadata); frame-rate resampling, the time window and downscaling are done by ffmpeg's
own filters so a 4K clip never exists in memory at full size.
"""

from __future__ import annotations

import hashlib
import logging
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError, UsageError
from ..files import regular_size

VIDEO_SUFFIXES = (".mp4", ".mov", ".avi", ".mkv", ".webm", ".m4v")
IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp")
DEFAULT_MAX_SIZE = 854  # longest side in pixels: DAVIS 480p; keeps flow and GrabCut affordable on a CPU
DEFAULT_FOLDER_FPS = 30.0
# Preprocessing holds, per stored pixel: RGB (3 B), forward and backward flow (16 B), occlusion and
# mask bytes, grey copies and the segmenter's working images: about 32 bytes. `decode` holds every
# frame, so its budget bounds the length; `video add` streams, so its budget bounds a frame's size.
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
    one-frame video) into memory; `open_video` streams it instead.

    ``fps`` resamples a video file; for a folder it declares the images' rate (default 30).
    ``start``/``end`` are seconds; ``max_frames`` keeps the first N after those; ``max_size`` bounds
    the longest side (0 or None: keep the original size). ``max_memory_gb`` bounds what
    preprocessing all the decoded frames at once would take (``BYTES_PER_PIXEL`` per stored
    pixel); a video over it is refused before (or while) decoding, with a hint (None: no bound).
    """
    budget = _Budget(max_memory_gb)
    stream = open_video(path, fps, start, end, max_frames, max_size)
    w, h = stream.size
    if stream.total is not None:
        budget.check(stream.total, w, h, estimate=stream.kind == "file")
    frames: list[np.ndarray] = []
    for frame in stream:
        frames.append(frame)
        budget.check(len(frames), w, h)  # a file's header duration may be missing or lie
        if progress:
            progress(len(frames), stream.total)
    return DecodedVideo(
        frames=np.stack(frames),
        fps=stream.fps,
        kind=stream.kind,
        path=stream.path,
        sha256=stream.sha256,
        original_size=stream.original_size,
        source_fps=stream.source_fps,
        source_indices=stream.source_indices,
        annotations=stream.annotations,
        image_files=stream.image_files,
        source_frames=stream.source_frames,
    )


def check_window(
    path: Path,
    fps: float | None = None,
    start: float | None = None,
    end: float | None = None,
    max_frames: int | None = None,
) -> Path:
    """``path`` expanded, once it exists and the window options make sense; else a clear error."""
    path = Path(path).expanduser()
    if not path.exists():
        raise InputError(
            f"{path} does not exist",
            hint="give a video file (.mp4 .mov .avi .mkv .webm) or a folder of images",
        )
    if not path.is_dir():
        regular_size(path, "the video", None)  # a FIFO or a device would block or never end
    if fps is not None and not (0 < fps <= 1000):
        raise UsageError(f"--fps {fps} is not a frame rate", hint="give a positive number such as 30")
    if start is not None and start < 0:
        raise UsageError(f"--start {start} is negative", hint="times are seconds from the start of the video")
    if start is not None and end is not None and end <= start:
        raise UsageError(f"--end {end} is not after --start {start}", hint="give a window with end > start")
    if max_frames is not None and max_frames < 1:
        raise UsageError(f"--max-frames {max_frames} must be at least 1")
    if not (path.is_dir() or path.suffix.lower() in IMAGE_SUFFIXES + VIDEO_SUFFIXES):
        raise InputError(
            f"{path.name}: not a video file zooctl reads ({path.suffix or 'no suffix'})",
            hint=f"use one of {' '.join(VIDEO_SUFFIXES)}, an image, or a folder of images",
        )
    return path


@dataclass
class SourceInfo:
    """What a video holds before decoding: its rate and length (``frames`` at ``fps`` in
    ``duration`` seconds; a file's from its header, None when the header does not say)."""

    fps: float
    duration: float | None
    frames: int | None
    size: tuple[int, int]  # (width, height) before downscaling; (0, 0) for a folder until read


def probe(path: str | Path, fps: float | None = None) -> SourceInfo:
    """A video's rate and length without decoding it (a folder: its images at ``fps``, default 30)."""
    path = check_window(Path(path), fps)
    if path.is_dir() or path.suffix.lower() in IMAGE_SUFFIXES:
        files = _folder_files(path)[2]
        rate = float(fps) if fps else DEFAULT_FOLDER_FPS
        return SourceInfo(rate, len(files) / rate, len(files), (0, 0))
    if path.stat().st_size == 0:
        raise InputError(f"{path.name} is empty (0 bytes)", hint="re-export or re-copy the video")
    size, src_fps, duration = _probe(path)
    src_fps = src_fps if src_fps > 0 else DEFAULT_FOLDER_FPS
    return SourceInfo(src_fps, duration, int(round(duration * src_fps)) if duration else None, size)


def open_video(
    path: str | Path,
    fps: float | None = None,
    start: float | None = None,
    end: float | None = None,
    max_frames: int | None = None,
    max_size: int | None = DEFAULT_MAX_SIZE,
    every: int = 1,
) -> VideoStream:
    """``path`` as a `VideoStream`: its metadata now, its frames one at a time as it is iterated.

    Options as `decode`'s; ``every`` keeps one source frame in ``every`` (a file: at the source
    rate, unless ``fps`` resamples it; the kept rate is the rate over ``every``)."""
    path = check_window(Path(path), fps, start, end, max_frames)
    if every < 1:
        raise UsageError(f"every {every} must be at least 1")
    if path.is_dir() or path.suffix.lower() in IMAGE_SUFFIXES:
        return _FolderStream(path, fps, start, end, max_frames, max_size, every)
    return _FileStream(path, fps, start, end, max_frames, max_size, every)


class VideoStream:
    """A video decoded frame by frame: iterate it once for (H, W, 3) uint8 RGB frames at ``size``.

    ``total``: the frames it should give (a file's from its header: approximate; None unknown).
    ``sha256`` and ``source_indices`` are complete once the iteration ends (a truncated file gives
    fewer frames than ``total``)."""

    kind: str
    path: Path
    fps: float
    source_fps: float
    original_size: tuple[int, int]
    size: tuple[int, int]
    total: int | None
    source_frames: int | None
    annotations: Path | None = None
    image_files: list[Path]
    sha256: str = ""
    source_indices: np.ndarray

    def __iter__(self) -> Iterator[np.ndarray]:  # pragma: no cover - each kind defines it
        raise NotImplementedError


class _Budget:
    """Refuses a video whose frames would need more than ``gb`` of preprocessing memory."""

    def __init__(self, gb: float | None) -> None:
        if gb is not None and not gb > 0:
            raise UsageError(f"--max-memory {gb} must be positive", hint="give gigabytes, e.g. 4")
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


def check_frame_memory(w: int, h: int, frames: int, gb: float | None) -> None:
    """Refuse frames so large that preprocessing ``frames`` of them at once (the streaming chunk)
    would need more than ``gb`` (``BYTES_PER_PIXEL`` per pixel); the clip's length does not count."""
    if gb is not None and not gb > 0:
        raise UsageError(f"--max-memory {gb} must be positive", hint="give gigabytes, e.g. 4")
    need = (frames + 1) * w * h * BYTES_PER_PIXEL / 1e9
    if gb is not None and need > gb:
        raise InputError(
            f"frames of {w}x{h} need about {need:.1f} GB to preprocess ({frames} at a time), "
            f"over the --max-memory limit of {gb:g} GB",
            hint="give a smaller --max-size (default 854), or raise --max-memory",
        )


# -- folders --------------------------------------------------------------------------------------


def _folder_files(folder: Path) -> tuple[str, Path | None, list[Path]]:
    """(kind, annotations folder or None, image files) of a folder, a DAVIS folder or one image."""
    kind, annotations, img_dir = "images", None, folder
    if folder.is_file():  # one photo: the folder of that one image
        return kind, None, [folder]
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
    return kind, annotations, files


class _FolderStream(VideoStream):
    def __init__(self, folder, fps, start, end, max_frames, max_size, every) -> None:
        from .images import open_image

        self.kind, self.annotations, files = _folder_files(folder)
        rate = float(fps) if fps else DEFAULT_FOLDER_FPS
        first = int(np.ceil((start or 0.0) * rate - 1e-9))
        last = len(files) if end is None else min(len(files), int(np.ceil(end * rate - 1e-9)))
        indices = np.arange(first, last)[::every]
        if max_frames is not None:
            indices = indices[:max_frames]
        if indices.size == 0:
            raise InputError(
                f"no frames of {folder} fall in the window --start {start} --end {end}",
                hint=f"it has {len(files)} images at {rate:g} fps",
            )
        self.path = folder.resolve()
        self.fps, self.source_fps = rate / every, rate
        self.source_indices = indices.astype(np.int64)
        self.image_files = [files[i] for i in indices]
        self.source_frames, self.total = len(files), len(indices)
        try:
            with open_image(self.image_files[0]) as im:
                self.original_size = im.size
        except InputError:
            raise
        except Exception as exc:
            raise InputError(
                f"{self.image_files[0]} is not a readable image: {exc}", hint="remove or replace that file"
            ) from None
        self.size = scaled_size(*self.original_size, max_size)
        self._digest = hashlib.sha256()

    def __iter__(self) -> Iterator[np.ndarray]:
        from PIL import Image

        from .images import open_image

        orig, size = self.original_size, self.size
        for f in self.image_files:
            data = f.read_bytes()
            self._digest.update(f.name.encode() + b"\0" + data)
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
            if rgb.size != orig:
                raise InputError(
                    f"{f.name} is {rgb.size[0]}x{rgb.size[1]}, the first image is {orig[0]}x{orig[1]}",
                    hint="every frame of a video must have the same size",
                )
            if rgb.size != size:
                rgb = rgb.resize(
                    size, Image.Resampling.BOX if size[0] < orig[0] else Image.Resampling.BICUBIC
                )
            yield np.asarray(rgb, dtype=np.uint8)
        self.sha256 = self._digest.hexdigest()


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


class _FileStream(VideoStream):
    def __init__(self, path, fps, start, end, max_frames, max_size, every) -> None:
        if path.stat().st_size == 0:
            raise InputError(f"{path.name} is empty (0 bytes)", hint="re-export or re-copy the video")
        (ow, oh), src_fps, duration = _probe(path)
        if src_fps <= 0:
            src_fps = DEFAULT_FOLDER_FPS
        w, h = scaled_size(ow, oh, max_size)
        rate = (float(fps) if fps else src_fps) / every
        filters = []
        if fps or every > 1:
            filters.append(f"fps={rate:.6f}")
        if (w, h) != (ow, oh):
            filters.append(f"scale={w}:{h}:flags=area")
        self._input_params = ["-ss", f"{start:.6f}"] if start else []
        out = []
        if end is not None:
            out += ["-t", f"{end - (start or 0.0):.6f}"]
        if filters:
            out += ["-vf", ",".join(filters)]
        if max_frames is not None:
            out += ["-frames:v", str(int(max_frames))]
        self._output_params = out
        self.total = None
        if duration:
            span = (min(end, duration) if end is not None else duration) - (start or 0.0)
            self.total = max(int(round(span * rate)), 0)
            if max_frames is not None:
                self.total = min(self.total, max_frames)
        self.kind, self.path, self.image_files = "file", path.resolve(), []
        self.fps, self.source_fps = rate, src_fps
        self.original_size, self.size = (ow, oh), (w, h)
        self.source_frames = int(round(duration * src_fps)) if duration else None
        self._start, self._end = start, end
        self.source_indices = np.zeros(0, np.int64)

    def __iter__(self) -> Iterator[np.ndarray]:
        import imageio_ffmpeg

        path, n = self.path, 0
        # imageio-ffmpeg logs a warning whenever the output size differs from the source: that is our scaling
        logging.getLogger("imageio_ffmpeg").setLevel(logging.ERROR)
        gen = imageio_ffmpeg.read_frames(
            str(path), pix_fmt="rgb24", input_params=self._input_params, output_params=self._output_params
        )
        try:
            meta = next(gen)
            fw, fh = meta["size"]
            for buf in gen:
                n += 1
                yield np.frombuffer(buf, dtype=np.uint8).reshape(fh, fw, 3)
        except (RuntimeError, OSError) as exc:
            if not n:
                raise InputError(
                    f"{path.name} could not be decoded: {_short(exc)}",
                    hint="check that the file is complete and plays in a video player",
                ) from None
            # a truncated file: keep the frames that decoded, as players do
        finally:
            gen.close()
        if not n:
            start, end = self._start, self._end
            window = f" in the window --start {start} --end {end}" if start or end is not None else ""
            raise InputError(
                f"{path.name} has no video frames{window}", hint="check the file and the time window"
            )
        t0 = self._start or 0.0
        self.source_indices = np.round((t0 + np.arange(n) / self.fps) * self.source_fps).astype(np.int64)
        self.sha256 = file_sha256(path)
