"""`video export`: frames as JPEG, masks as PNG, flow as .npy plus occlusion PNGs, written into a folder."""

from __future__ import annotations

import contextlib
import io
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..errors import UsageError, ZooctlError

WHAT = ("frames", "masks", "flow")


def _out_folder(out: Path) -> None:
    """Create the folder ``out``, or say in one line why it cannot be one."""
    if out.exists() and not out.is_dir():
        raise UsageError(f"-o {out} is not a folder", hint="give a new or existing folder to write into")
    with _writing(out):
        out.mkdir(parents=True, exist_ok=True)


@contextlib.contextmanager
def _writing(where: Path) -> Iterator[None]:
    """OSErrors of the export's writes (`temp_path` reports them as store errors) as one clear
    error that names the folder, a full disk above all."""
    import errno

    from ..errors import NoSpaceError, ReadOnlyStoreError

    try:
        yield
    except NoSpaceError as exc:
        hint = "free disk space (or raise the file-size limit) and export again"
        raise ZooctlError(exc.message, hint=hint) from None
    except ReadOnlyStoreError:
        raise UsageError(f"cannot write into {where}: permission denied", hint="choose another -o") from None
    except OSError as exc:
        why = exc.strerror or str(exc)
        if exc.errno in (errno.ENOSPC, errno.EFBIG, errno.EDQUOT):
            raise ZooctlError(
                f"no space left on device / file too large while exporting into {where}: {why}",
                hint="free disk space (or raise the file-size limit) and export again",
            ) from None
        raise ZooctlError(f"cannot write into {where}: {why}", hint="choose another -o") from None


def export_video(store, name: str, what: str, out: str | Path) -> int:
    """Write one part of a stored video into ``out``; returns how many files were written.

    frames: ``00000.jpg``...; masks: ``00000.png`` (0/255); flow: ``forward.npy`` and
    ``backward.npy`` (T-1, H, W, 2) float32 pixels, ``occlusion_forward/00000.png``... (255: occluded).
    Each file is written to a temporary and renamed, so a reader never sees half a file.
    """
    from ..store.video_reader import StoredVideo

    if what not in WHAT:
        raise UsageError(f"--what {what!r} is not one of {', '.join(WHAT)}")
    store.summary(name)  # an unknown name: NotFoundError
    with StoredVideo(store.path(name)) as rec:  # read a few frames at a time
        return _export(rec, what, Path(out))


def _export(rec, what: str, out: Path) -> int:
    from PIL import Image

    from ..store.fs import publish, temp_path

    _out_folder(out)
    n = 0

    def save_image(arr: np.ndarray, final: Path, fmt: str) -> None:
        with _writing(out):
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
            with _writing(out):
                tmp = temp_path(final)
                try:
                    _write_npy(tmp, arr)
                    publish(tmp, final)
                finally:
                    tmp.unlink(missing_ok=True)
            n += 1
        for key, arr in (
            ("occlusion_forward", rec.occlusion_forward),
            ("occlusion_backward", rec.occlusion_backward),
        ):
            with _writing(out):
                (out / key).mkdir(exist_ok=True)
            for i, m in enumerate(arr):
                save_image(m.astype(np.uint8) * 255, out / key / f"{i:05d}.png", "PNG")
                n += 1
    return n


def _write_npy(path: Path, arr) -> None:
    """``arr`` (a `FrameArray`) as a float32 ``.npy`` file, written a chunk of frames at a time
    with plain writes (np.save into a file fails without an errno on a full disk)."""
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        header,
        {"descr": np.lib.format.dtype_to_descr(np.dtype("<f4")), "fortran_order": False, "shape": arr.shape},
    )
    with open(path, "wb") as f:
        f.write(header.getvalue())
        for _, chunk in arr.chunks():
            f.write(np.ascontiguousarray(chunk, "<f4").tobytes())
