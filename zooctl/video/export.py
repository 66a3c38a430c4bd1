"""`video export`: frames as JPEG, masks as PNG, flow as .npy plus occlusion PNGs, written into a folder."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import UsageError

WHAT = ("frames", "masks", "flow")


def export_video(store, name: str, what: str, out: str | Path) -> int:
    """Write one part of a stored video into ``out``; returns how many files were written.

    frames: ``00000.jpg``...; masks: ``00000.png`` (0/255); flow: ``forward.npy`` and
    ``backward.npy`` (T-1, H, W, 2) float32 pixels, ``occlusion_forward/00000.png``... (255: occluded).
    Each file is written to a temporary and renamed, so a reader never sees half a file.
    """
    from PIL import Image

    from ..store.fs import publish, temp_path

    if what not in WHAT:
        raise UsageError(f"--what {what!r} is not one of {', '.join(WHAT)}")
    parts = {"frames": ("frames",), "masks": ("masks",), "flow": ("flow",)}[what]
    rec = store.get(name, what=parts)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    n = 0

    def save_image(arr: np.ndarray, final: Path, fmt: str) -> None:
        tmp = temp_path(final)
        try:
            Image.fromarray(arr).save(tmp, format=fmt, **({"quality": 95} if fmt == "JPEG" else {}))
            publish(tmp, final)
        finally:
            tmp.unlink(missing_ok=True)

    if what == "frames":
        for i, f in enumerate(rec.frames):
            save_image(f, out / f"{i:05d}.jpg", "JPEG")
            n += 1
    elif what == "masks":
        for i, m in enumerate(rec.masks):
            save_image(m.astype(np.uint8) * 255, out / f"{i:05d}.png", "PNG")
            n += 1
    else:
        for key, arr in (("forward", rec.flow_forward), ("backward", rec.flow_backward)):
            final = out / f"{key}.npy"
            tmp = temp_path(final)
            try:
                with open(tmp, "wb") as fh:
                    np.save(fh, arr.astype(np.float32))
                publish(tmp, final)
            finally:
                tmp.unlink(missing_ok=True)
            n += 1
        for key, arr in (
            ("occlusion_forward", rec.occlusion_forward),
            ("occlusion_backward", rec.occlusion_backward),
        ):
            (out / key).mkdir(exist_ok=True)
            for i, m in enumerate(arr):
                save_image(m.astype(np.uint8) * 255, out / key / f"{i:05d}.png", "PNG")
                n += 1
    return n
