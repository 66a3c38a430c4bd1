"""The lens a video was filmed with, read from its file, as a 35 mm-equivalent focal length.

A fit cannot tell the lens from silhouettes: a body stretched along the camera's axis by k, filmed
with a focal k times longer, casts the same image. So a lens the file records is worth more than
any estimate. Recorded by:

- iPhones and other Apple capture: the QuickTime metadata of .mov/.mp4 files (``moov/meta``, a
  ``keys`` list and an ``ilst`` of values), key ``com.apple.quicktime.camera.focal_length.
  35mm_equivalent`` (with ``com.apple.quicktime.camera.lens_model``); ffmpeg writes the same keys
  with ``-movflags use_metadata_tags``;
- cameras and phones in their photos' Exif: ``FocalLengthIn35mmFilm`` (tag 41989), read from the
  first image of a folder of frames.

A 35 mm-equivalent focal length gives the field of view that focal length has on a 36 x 24 mm frame,
matched along the diagonal (CIPA DC-004): in pixels, ``f35 / 43.27 x`` the frame's diagonal.
"""

from __future__ import annotations

import math
import struct
from pathlib import Path
from typing import Any, BinaryIO

from .decode import IMAGE_SUFFIXES

FULL_FRAME_DIAGONAL_MM = math.hypot(36.0, 24.0)
QUICKTIME_FOCAL_KEY = "com.apple.quicktime.camera.focal_length.35mm_equivalent"
QUICKTIME_LENS_KEY = "com.apple.quicktime.camera.lens_model"
EXIF_IFD = 0x8769
EXIF_FOCAL_35MM = 41989
EXIF_LENS_MODEL = 0xA434
MIN_FOCAL_35MM, MAX_FOCAL_35MM = 1.0, 5000.0  # a fisheye to a long telephoto
_MAX_MOOV_BYTES = 64 << 20  # a moov atom is a few MB even for long clips: bound what is read
_CONTAINERS = {b"moov", b"udta", b"meta"}


def focal_pixels(focal_35mm: float, width: int, height: int) -> float:
    """The focal length in pixels of ``width`` x ``height`` frames filmed with a lens of
    ``focal_35mm`` mm 35 mm-equivalent (module docstring)."""
    return focal_35mm / FULL_FRAME_DIAGONAL_MM * math.hypot(width, height)


_FROM = {
    "user": "given with --lens",
    "config": "--lens",  # zooctl fit --lens (camera.lens_35mm), `zooctl.fit.focal`
    "quicktime": "the file's QuickTime metadata",
    "exif": "the first frame's Exif",
}


def lens_line(lens: dict[str, Any]) -> str:
    """One line saying what a stored lens (`read_lens`'s dict) is and where it came from."""
    model = f", {lens['lens_model']}" if lens.get("lens_model") else ""
    return (
        f"lens: {lens['focal_35mm']:g} mm 35 mm-equivalent{model} ({_FROM.get(lens['from'], lens['from'])})"
    )


def read_lens(path: Path) -> dict[str, Any] | None:
    """``{"focal_35mm": mm, "lens_model": str | None, "from": "quicktime" | "exif"}`` from a video
    file's QuickTime metadata or a folder's first image's Exif; None when the file records no lens
    (or cannot be read: the lens is a hint, never a reason to refuse a video)."""
    path = Path(path)
    try:
        if path.is_dir() or path.suffix.lower() in IMAGE_SUFFIXES:
            return _image_lens(path)
        with open(path, "rb") as f:
            items = _quicktime_items(f)
    except (OSError, ValueError, struct.error, SyntaxError):  # PIL raises SyntaxError for bad files
        return None
    focal = _positive(items.get(QUICKTIME_FOCAL_KEY))
    if focal is None:
        return None
    model = items.get(QUICKTIME_LENS_KEY)
    model = model if isinstance(model, str) and model else None
    return {"focal_35mm": focal, "lens_model": model, "from": "quicktime"}


def _positive(value: Any) -> float | None:
    try:
        v = float(value)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) and MIN_FOCAL_35MM <= v <= MAX_FOCAL_35MM else None


def _image_lens(path: Path) -> dict[str, Any] | None:
    """The Exif lens of a frame folder's (or DAVIS folder's) first image, or of one image."""
    from PIL import Image

    from ..errors import InputError
    from .decode import _folder_files

    try:
        first = _folder_files(path)[2][0]
    except InputError:
        return None
    with Image.open(first) as im:
        ifd = im.getexif().get_ifd(EXIF_IFD)
    focal = _positive(ifd.get(EXIF_FOCAL_35MM))
    if focal is None:
        return None
    model = str(ifd.get(EXIF_LENS_MODEL) or "").strip("\x00 ")
    return {"focal_35mm": focal, "lens_model": model or None, "from": "exif"}


def _atoms(f: BinaryIO, start: int, end: int):
    """(type, payload start, payload end) of the atoms between byte offsets ``start`` and ``end``."""
    pos = start
    while pos + 8 <= end:
        f.seek(pos)
        size, kind = struct.unpack(">I4s", f.read(8))
        head = 8
        if size == 1:
            (size,) = struct.unpack(">Q", f.read(8))
            head = 16
        elif size == 0:
            size = end - pos
        if size < head or pos + size > end:
            return
        yield kind, pos + head, pos + size
        pos += size


def _quicktime_items(f: BinaryIO) -> dict[str, Any]:
    """The ``mdta`` key -> value pairs of a QuickTime/MP4 file's ``moov/meta`` (and ``moov/udta/meta``)."""
    f.seek(0, 2)
    size = f.tell()
    for kind, a, b in _atoms(f, 0, size):
        if kind == b"moov":
            if b - a > _MAX_MOOV_BYTES:
                return {}
            f.seek(a)
            return _moov_items(f.read(b - a))
    return {}


def _moov_items(moov: bytes) -> dict[str, Any]:
    import io

    f = io.BytesIO(moov)
    out: dict[str, Any] = {}

    def walk(start: int, end: int) -> None:
        for kind, a, b in _atoms(f, start, end):
            if kind == b"meta":
                f.seek(a + 4)
                # QuickTime's meta holds atoms at once; ISO's is a full box (4 bytes of version, flags)
                a += 0 if f.read(4) in (b"hdlr", b"keys", b"ilst") else 4
                out.update(_meta_items(f, a, b))
            elif kind in _CONTAINERS:
                walk(a, b)

    walk(0, len(moov))
    return out


def _meta_items(f: BinaryIO, start: int, end: int) -> dict[str, Any]:
    keys: list[str] = []
    values: dict[int, Any] = {}
    for kind, a, b in _atoms(f, start, end):
        if kind == b"keys":
            f.seek(a + 4)  # version, flags
            (count,) = struct.unpack(">I", f.read(4))
            pos = a + 8
            for _ in range(count):
                f.seek(pos)
                size, namespace = struct.unpack(">I4s", f.read(8))
                if size < 8 or pos + size > b:
                    break
                keys.append(f.read(size - 8).decode("utf-8", "replace") if namespace == b"mdta" else "")
                pos += size
        elif kind == b"ilst":
            for index, ia, ib in _atoms(f, a, b):
                for dkind, da, db in _atoms(f, ia, ib):
                    if dkind == b"data" and db - da >= 8:
                        f.seek(da)
                        type_code = struct.unpack(">I", f.read(4))[0] & 0xFFFFFF
                        f.read(4)  # locale
                        values[struct.unpack(">I", index)[0]] = _value(type_code, f.read(db - da - 8))
                        break
    return {keys[i - 1]: v for i, v in values.items() if 1 <= i <= len(keys) and keys[i - 1]}


def _value(type_code: int, raw: bytes) -> Any:
    """A QuickTime well-known data type (1 UTF-8, 21/22 big-endian signed/unsigned integers, 23/24
    big-endian floats); None for others."""
    if type_code == 1:
        return raw.decode("utf-8", "replace").strip("\x00 ")
    if type_code in (21, 22) and len(raw) in (1, 2, 4, 8):
        return int.from_bytes(raw, "big", signed=type_code == 21)
    if type_code == 23 and len(raw) == 4:
        return struct.unpack(">f", raw)[0]
    if type_code == 24 and len(raw) == 8:
        return struct.unpack(">d", raw)[0]
    return None
