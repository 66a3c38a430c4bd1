"""Per-frame working arrays kept in an unlinked temporary file instead of in memory.

Preprocessing a long video needs, per frame, things that later steps read back in any order (the
segmenter's downscaled frames, colour bins and masks, the flow at its working size). `ScratchArray`
holds them as fixed-size records on disk, read and written one frame at a time with ``pread`` /
``pwrite``: the process holds only the frames it is working on, the kernel's page cache does the
rest, and the file vanishes when closed or when the process dies (it is unlinked at creation).
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..store.fs import writing


class ScratchArray:
    """An (N, *shape) array of ``dtype`` in a temporary file, indexed by frame like a NumPy array.

    ``a[i]`` returns a fresh (shape) array; ``a[i] = x`` writes one record; ``a[i:j]`` and
    ``a[[i, j]]`` stack records; records never written read as zeros. ``dir``: where the file lives
    (the store's folder keeps it on the disk the video goes to; None: the system's temp folder).
    """

    def __init__(self, n: int, shape: tuple[int, ...], dtype, dir: str | Path | None = None) -> None:
        self.dtype = np.dtype(dtype)
        self.shape = (int(n), *(int(s) for s in shape))
        self._item = int(np.prod(self.shape[1:], dtype=np.int64)) * self.dtype.itemsize
        self._where = f"writing scratch data in {dir or tempfile.gettempdir()}"
        with writing(self._where):
            self._file = tempfile.TemporaryFile(
                prefix=".zooctl-scratch-", dir=None if dir is None else str(dir)
            )
            self._fd = self._file.fileno()
            os.ftruncate(self._fd, self.shape[0] * self._item)  # sparse: unwritten records are zeros

    @property
    def ndim(self) -> int:
        return len(self.shape)

    def __len__(self) -> int:
        return self.shape[0]

    def _index(self, i: int) -> int:
        i = int(i)
        if i < 0:
            i += self.shape[0]
        if not 0 <= i < self.shape[0]:
            raise IndexError(f"index {i} out of range for {self.shape[0]} records")
        return i

    def read(self, i: int) -> np.ndarray:
        i = self._index(i)
        buf = os.pread(self._fd, self._item, i * self._item)
        if len(buf) != self._item:
            raise OSError(f"short read from a scratch file ({len(buf)} of {self._item} bytes)")
        return np.frombuffer(buf, self.dtype).reshape(self.shape[1:]).copy()

    def write(self, i: int, value) -> None:
        i = self._index(i)
        data = np.ascontiguousarray(np.broadcast_to(np.asarray(value, self.dtype), self.shape[1:]))
        view = memoryview(data).cast("B")
        done = 0
        with writing(self._where):  # a full disk: one clear error
            while done < self._item:
                done += os.pwrite(self._fd, view[done:], i * self._item + done)

    def __getitem__(self, key):
        if isinstance(key, (int, np.integer)):
            return self.read(key)
        idx = range(self.shape[0])[key] if isinstance(key, slice) else np.asarray(key).ravel()
        out = np.empty((len(idx), *self.shape[1:]), self.dtype)
        for k, i in enumerate(idx):
            out[k] = self.read(i)
        return out

    def append(self, value) -> None:
        """Add a record at the end (the file grows; one record at a time)."""
        n = self.shape[0]
        with writing(self._where):
            os.ftruncate(self._fd, (n + 1) * self._item)
        self.shape = (n + 1, *self.shape[1:])
        self.write(n, value)

    def __setitem__(self, key, value) -> None:
        if not isinstance(key, (int, np.integer)):
            raise TypeError("a scratch array is written one record at a time")
        self.write(key, value)

    def __iter__(self) -> Iterator[np.ndarray]:
        for i in range(self.shape[0]):
            yield self.read(i)

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        out = self[:]
        return out if dtype is None else out.astype(dtype)

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> ScratchArray:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def working(like, n: int, shape: tuple[int, ...], dtype) -> np.ndarray | ScratchArray:
    """A zeroed (n, *shape) buffer that lives where ``like`` does: in memory for a NumPy array
    (the caller holds the whole video anyway), else in a `ScratchArray`."""
    if isinstance(like, np.ndarray):
        return np.zeros((n, *shape), dtype)
    return ScratchArray(n, shape, dtype)


class Resized:
    """A lazy view of (T, h, w) masks at another size (w, h): frame i is upsampled when read,
    with a linear upsample of the 0/1 values thresholded at one half, or by ``upsample(i, mask)``
    -> (h, w) bool when given."""

    dtype = np.dtype(bool)
    ndim = 3

    def __init__(self, masks, w: int, h: int, upsample=None) -> None:
        self._masks = masks
        self._upsample = upsample
        self.shape = (len(masks), h, w)

    def __len__(self) -> int:
        return self.shape[0]

    def _one(self, i) -> np.ndarray:
        import cv2

        if self._upsample is not None:
            return self._upsample(int(i), np.asarray(self._masks[int(i)], bool))
        m = np.asarray(self._masks[int(i)], np.float32)
        return cv2.resize(m, (self.shape[2], self.shape[1]), interpolation=cv2.INTER_LINEAR) > 0.5

    def __getitem__(self, key):
        if isinstance(key, (int, np.integer)):
            return self._one(key)
        idx = range(self.shape[0])[key] if isinstance(key, slice) else np.asarray(key).ravel()
        return np.stack([self._one(i) for i in idx]) if len(idx) else np.zeros((0, *self.shape[1:]), bool)

    def __iter__(self) -> Iterator[np.ndarray]:
        return (self._one(i) for i in range(self.shape[0]))

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        out = self[:]
        return out if dtype is None else out.astype(dtype)
