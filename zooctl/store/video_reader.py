"""A stored video read a few frames at a time, so memory does not grow with the video's length.

`StoredVideo` opens one video file of the store (`zooctl.store.videos`) read-only and keeps it
open: its small parts (attributes, boxes, source indices) are read at once, its per-frame
datasets are `FrameArray` s that read what they are indexed with. The fit, `video show
--preview` and `video export` hold masks and a few frames, never a whole video's frames and flow.
Every read is checked against the array read limit (``ZOOCTL_MAX_ARRAY_MB``) at the size it
allocates (float16 flow counts as the float32 it becomes), so a crafted file cannot make one read
allocate past the limit.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import StoreError
from ..limits import check_read
from .h5 import open_h5

CHUNK = 16  # frames per read when iterating: a few MB at 854x480
HINT = "remove it with `zooctl video rm` and add it again"
_SMALL = ["boxes", "source_indices"]  # read whole when the file opens


class FrameArray:
    """A read-only (T, ...) array of one per-frame dataset of an open `StoredVideo`.

    Indexing reads: ``a[t]``, ``a[s:e]`` (step 1), ``a[index_array]`` and those followed by
    slices of the other axes (``a[s:e, y0:y1, x0:x1]``: only that window is kept) return numpy
    arrays of ``dtype``; ``head(n)`` is the first ``n`` frames and ``part(start, stop)`` frames
    ``start`` to ``stop``, both still unread (indexed from their first frame); iterating yields one
    frame at a time, read `CHUNK` at once; ``np.asarray(a)`` reads it all (within the limit)."""

    def __init__(
        self,
        video: StoredVideo,
        key: str,
        dtype: Any,
        convert: Callable[[np.ndarray], np.ndarray] | None = None,
        length: int | None = None,
        start: int = 0,
    ) -> None:
        self._video, self._key = video, key
        self._ds = video.file[key]
        self.dtype = np.dtype(dtype)
        self._convert = convert
        self._start = min(max(0, int(start)), int(self._ds.shape[0]))
        n = int(self._ds.shape[0]) - self._start
        self._len = n if length is None else min(n, max(0, int(length)))

    @property
    def shape(self) -> tuple[int, ...]:
        return (self._len, *(int(s) for s in self._ds.shape[1:]))

    def close(self) -> None:
        """Close the file this array reads (`StoredVideo.close`): every array of it, after."""
        self._video.close()

    @property
    def ndim(self) -> int:
        return len(self._ds.shape)

    def __len__(self) -> int:
        return self._len

    def head(self, n: int) -> FrameArray:
        """The first ``n`` frames, unread."""
        return self.part(0, n)

    def part(self, start: int, stop: int) -> FrameArray:
        """Frames ``start`` to ``stop`` (clipped to this array), unread."""
        start, stop = min(max(0, int(start)), self._len), min(max(0, int(stop)), self._len)
        return FrameArray(
            self._video, self._key, self.dtype, self._convert, max(0, stop - start), self._start + start
        )

    def __iter__(self) -> Iterator[np.ndarray]:
        for s in range(0, self._len, CHUNK):
            yield from self[s : min(s + CHUNK, self._len)]

    def chunks(self, size: int = CHUNK) -> Iterator[tuple[int, np.ndarray]]:
        """(start, frames[start:start + size]) pairs over the whole array."""
        for s in range(0, self._len, size):
            yield s, self[s : min(s + size, self._len)]

    def __array__(self, dtype: Any = None, copy: Any = None) -> np.ndarray:
        out = self[0 : self._len]
        return out if dtype is None else out.astype(dtype)

    def __getitem__(self, key: Any) -> np.ndarray:
        first, rest = (key[0], key[1:]) if isinstance(key, tuple) else (key, ())
        if any(not isinstance(r, slice) for r in rest):
            raise TypeError("a stored video's arrays take slices after the frame index")
        single = isinstance(first, (int, np.integer))
        if single:
            t = int(first) + (self._len if first < 0 else 0)
            if not 0 <= t < self._len:
                raise IndexError(f"frame {int(first)} of {self._len}")
            frames: Any = [t]
        elif isinstance(first, slice):
            start, stop, step = first.indices(self._len)
            if step != 1:
                raise TypeError("a stored video's arrays take slices with step 1")
            frames = range(start, max(start, stop))
        else:
            idx = np.asarray(first)
            if idx.dtype == bool:
                idx = np.nonzero(idx)[0]
            idx = idx.astype(np.int64).ravel()
            if len(idx) and (idx.min() < -self._len or idx.max() >= self._len):
                raise IndexError(f"frame index out of range for {self._len} frames")
            frames = [int(i) % self._len for i in idx]
        window = tuple(slice(*r.indices(s)) for r, s in zip(rest, self._ds.shape[1:]))
        inner = tuple(len(range(w.start, w.stop, w.step)) for w in window) + self._ds.shape[1 + len(window) :]
        nbytes = len(frames) * math.prod(inner) * self.dtype.itemsize
        check_read(
            f"{self._video.what} {self._video.path}: {len(frames)} frames of {self._key} take",
            nbytes,
            "max_array_mb",
            StoreError,
        )
        out = np.empty((len(frames), *inner), self.dtype)
        try:
            if isinstance(frames, range) and len(frames):
                for s in range(frames.start, frames.stop, CHUNK):  # contiguous: whole chunks
                    e = min(s + CHUNK, frames.stop)
                    out[s - frames.start : e - frames.start] = self._read(
                        np.s_[self._start + s : self._start + e], window
                    )
            else:
                # One read per frame: h5py's point selection over chunked, compressed data is
                # much slower than plain reads of whole chunks.
                for n, t in enumerate(frames):
                    out[n] = self._read(self._start + t, window)
        except (OSError, ValueError, TypeError, KeyError) as exc:
            raise StoreError(
                f"{self._video.what} {self._video.path} is unreadable: {exc}", hint=HINT
            ) from None
        return out[0] if single else out

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        return (FrameArray, (self._video, self._key, self.dtype, self._convert, self._len, self._start))

    def _read(self, where: Any, window: tuple[slice, ...]) -> np.ndarray:
        a = self._ds[(where, *window)]
        return a if self._convert is None else self._convert(a)


class StoredVideo:
    """One stored video file, open for reading (see the module docstring).

    frames (T, H, W, 3) uint8; masks (T, H, W) bool; flow_forward / flow_backward (T-1, H, W, 2)
    float32 pixels; flow_valid (T-1, H, W) bool: the forward-backward check passed (the stored
    occlusion's complement); all `FrameArray` s. boxes (T, 4) int32 x, y, w, h per mask (zeros:
    empty); source_indices (T,) int64; fps, name, source, segmenter, flow_estimator: attributes.
    """

    def __init__(self, path: Path, what: str = "the video file") -> None:
        self.path, self.what = Path(path), what
        self.file = open_h5(self.path, what, HINT, _SMALL)
        try:
            f = self.file
            if f.attrs.get("zooctl_kind") != "video":
                raise StoreError(f"{what} {path} is not a zooctl video file", hint=HINT)
            fd, md = f["frames"], f["masks"]
            self.boxes = np.asarray(f["boxes"][()], np.int32)
            self.source_indices = np.asarray(f["source_indices"][()], np.int64)
            T = int(fd.shape[0]) if len(fd.shape) == 4 else -1
            if (
                len(fd.shape) != 4
                or fd.shape[3] != 3
                or tuple(md.shape) != tuple(fd.shape[:3])
                or self.boxes.shape != (T, 4)
                or self.source_indices.shape != (T,)
            ):
                raise StoreError(
                    f"{what} {path} is damaged: frames {fd.shape}, masks {md.shape}, boxes "
                    f"{self.boxes.shape}, source indices {self.source_indices.shape} do not agree",
                    hint=HINT,
                )
            self.frames = FrameArray(self, "frames", np.uint8)
            self.masks = FrameArray(self, "masks", bool, _as_bool)
            pair = (T - 1, *fd.shape[1:3])
            flow = {
                k: f[f"flow/{k}"] for k in ("forward", "backward", "occlusion_forward", "occlusion_backward")
            }
            for k, ds in flow.items():
                want = (*pair, 2) if k in ("forward", "backward") else pair
                if tuple(ds.shape) != want:
                    raise StoreError(
                        f"{what} {path} is damaged: flow/{k} is {ds.shape}, not {want}", hint=HINT
                    )
            self.flow_forward = FrameArray(self, "flow/forward", np.float32, _as_float32)
            self.flow_backward = FrameArray(self, "flow/backward", np.float32, _as_float32)
            self.flow_valid = FrameArray(self, "flow/occlusion_forward", bool, _not)
            self.occlusion_forward = FrameArray(self, "flow/occlusion_forward", bool, _as_bool)
            self.occlusion_backward = FrameArray(self, "flow/occlusion_backward", bool, _as_bool)
            self.fps = float(f.attrs["fps"])
            self.name = str(f.attrs["name"])
            self.source = json.loads(f.attrs["source"])
            self.segmenter = json.loads(f.attrs["segmenter"])
            self.flow_estimator = json.loads(f.attrs["flow_estimator"])
        except StoreError:
            self.close()
            raise
        except (OSError, KeyError, ValueError, TypeError, AttributeError) as exc:
            self.close()
            raise StoreError(f"{what} {path} is damaged: {type(exc).__name__}: {exc}", hint=HINT) from None

    @property
    def num_frames(self) -> int:
        return len(self.frames)

    def close(self) -> None:
        try:
            self.file.close()
        except Exception:  # closing twice, or a handle already gone
            pass

    def __enter__(self) -> StoredVideo:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        return (StoredVideo, (self.path, self.what))  # an h5py handle cannot travel: reopen


def _as_bool(a: np.ndarray) -> np.ndarray:
    return a.astype(bool)


def _not(a: np.ndarray) -> np.ndarray:
    return a == 0


def _as_float32(a: np.ndarray) -> np.ndarray:
    return a.astype(np.float32)
