"""Opening the image files a user gives (video frames, masks) under our own size limit.

PIL guards against decompression bombs by itself: a warning printed over 89 megapixels, an error
over 179. A user saw the warning's text (or PIL's error wording) instead of one line from us; here
PIL's check is silenced and ours applies, before a pixel is decoded (a 40 KB PNG can declare
14,000 x 14,000 pixels).
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from ..errors import InputError

# One image, in megapixels: far above any video frame (8K is 33 MP) and the largest phone photos
# (108 MP), and below PIL's own refusal (179 MP), which this limit replaces.
MAX_IMAGE_MEGAPIXELS = 120


def too_large(path: Path, pixels: int, size: tuple[int, int] | None = None) -> InputError:
    what = (
        f"{size[0]}x{size[1]} ({pixels / 1e6:,.0f} megapixels)" if size else f"{pixels / 1e6:,.0f} megapixels"
    )
    return InputError(
        f"{path.name} is an image of {what}, over the limit of {MAX_IMAGE_MEGAPIXELS} megapixels",
        hint="downscale the images first (zooctl keeps at most --max-size pixels a side anyway)",
    )


@contextmanager
def open_image(path: str | Path) -> Iterator[Any]:
    """``PIL.Image.open(path)`` (lazy: only the header is read) as a context manager, refused with
    an `InputError` when the image is over `MAX_IMAGE_MEGAPIXELS`. Other failures (not an image,
    unreadable) are PIL's exceptions, as from ``Image.open``."""
    from PIL import Image

    path = Path(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", Image.DecompressionBombWarning)
        try:
            im = Image.open(path)
        except Image.DecompressionBombError as exc:  # over 179 MP: PIL says how many pixels
            found = re.search(r"\((\d+) pixels\)", str(exc))
            raise too_large(path, int(found.group(1)) if found else 0) from None
    with im:
        w, h = im.size
        if w * h > MAX_IMAGE_MEGAPIXELS * 1_000_000:
            raise too_large(path, w * h, (w, h))
        yield im
