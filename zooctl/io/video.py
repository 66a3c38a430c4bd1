"""Writing H.264 MP4 videos that play in a web browser.

OpenCV's wheel cannot encode H.264, so this drives the ffmpeg binary that the ``imageio-ffmpeg``
package ships (libx264, yuv420p, even frame size, ``+faststart`` for streaming).
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..store.fs import publish, temp_path


def _even(n: int) -> int:
    return n + (n % 2)


def write_mp4(
    path: str | Path, frames: Iterable[np.ndarray] | np.ndarray, fps: float = 30.0, quality: int = 23
) -> Path:
    """Write RGB uint8 frames (each (H, W, 3), all the same size) as an H.264 MP4, atomically.

    ``quality`` is x264's CRF (lower is better, 18-28 sensible). Odd sizes are padded by one pixel.
    Returns the path written.
    """
    import imageio_ffmpeg

    path = Path(path)
    it = iter(frames)
    try:
        first = np.asarray(next(it))
    except StopIteration:
        raise InputError(f"no frames to write to {path}") from None
    if first.ndim != 3 or first.shape[2] != 3:
        raise InputError(f"frames must be (H, W, 3) RGB, got {first.shape}")
    h, w = first.shape[:2]
    H, W = _even(h), _even(w)
    tmp = temp_path(path.with_suffix(".mp4")) if path.suffix.lower() != ".mp4" else temp_path(path)
    tmp_mp4 = tmp.with_name(tmp.name + ".mp4")  # ffmpeg picks the muxer from the suffix
    tmp.unlink(missing_ok=True)
    writer = imageio_ffmpeg.write_frames(
        str(tmp_mp4),
        (W, H),
        fps=float(fps),
        codec="libx264",
        pix_fmt_out="yuv420p",
        quality=None,
        output_params=["-crf", str(int(quality)), "-preset", "veryfast", "-movflags", "+faststart"],
        macro_block_size=1,
        ffmpeg_log_level="error",
    )
    writer.send(None)
    try:
        for f in _chain(first, it):
            f = np.asarray(f)
            if f.shape[:2] != (h, w):
                raise InputError(f"frame size changed from {(h, w)} to {f.shape[:2]} while writing {path}")
            if f.dtype != np.uint8:
                f = np.clip(f, 0, 255).astype(np.uint8)
            if (H, W) != (h, w):
                f = np.pad(f, ((0, H - h), (0, W - w), (0, 0)), mode="edge")
            writer.send(np.ascontiguousarray(f))
        writer.close()
        publish(tmp_mp4, path)
    except BaseException:
        writer.close()
        tmp_mp4.unlink(missing_ok=True)
        raise
    return path


def _chain(first: np.ndarray, rest: Iterable[np.ndarray]) -> Iterable[np.ndarray]:
    yield first
    yield from rest


def probe_codec(path: str | Path) -> str:
    """The codec name of the first video stream (for tests and `video show`), e.g. ``"h264"``."""
    import re
    import subprocess

    import imageio_ffmpeg

    out = subprocess.run(
        [imageio_ffmpeg.get_ffmpeg_exe(), "-hide_banner", "-i", str(path)], capture_output=True, text=True
    ).stderr
    m = re.search(r"Video: (\w+)", out)
    return m.group(1) if m else ""
