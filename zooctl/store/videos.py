"""The video store: one HDF5 file per preprocessed video plus a JSON index, crash-safe.

Layout under the store root (JSON Schemas: ``schemas/video_index.schema.json`` and
``schemas/video_h5.schema.json``)::

    videos/index.json      {"schema_version": 1, "videos": {name: summary}}  - what `video list` reads
    videos/<name>.h5       frames, masks, boxes, forward/backward flow, occlusion masks, source metadata
    videos/<name>.cache/   derived data (retrieval query embeddings), removed with the video

Same rules as the bank: the HDF5 file is written to a temporary beside its final path outside the
lock (the slow part: `video add` streams frames, flow and masks into it as they are made with a
`VideoWriter`; a video held in memory is built as a file image first), then under the store's
writers' lock the name is checked again, the file is fsynced and ``os.replace``d into place, and
the index is replaced last.
A failure at any point (a full disk included) leaves the store as it was (at worst an unindexed
temporary that `cleanup` removes). A missing or damaged index is an error naming
`zooctl video repair`, which rebuilds it from the video files (`zooctl.store.indexed`).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import shutil
import sys
import threading
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import StoreError
from ..limits import check_read
from ..names import check_name
from .fs import h5_image, temp_path, writing
from .h5 import open_h5, read_h5
from .indexed import INDEX_VERSION, IndexedStore

__all__ = ["INDEX_VERSION", "FILE_VERSION", "VideoRecord", "VideoStore"]
FILE_VERSION = 1
_GZIP = 3  # masks and occlusion (0/1 maps: small either way)


@dataclass
class VideoRecord:
    """A preprocessed video, as stored.

    ``frames`` (T, H, W, 3) uint8 RGB; ``masks`` (T, H, W) bool; ``flow_forward`` / ``flow_backward``
    (T-1, H, W, 2) float32 pixels (t -> t+1 and t+1 -> t); ``occlusion_forward`` / ``occlusion_backward``
    (T-1, H, W) bool (forward-backward check failed, see `zooctl.video.flow.VideoFlow`);
    ``source_indices`` (T,) int64 frame index in the source; ``source`` is metadata (path, kind,
    sha256, fps, original_width, original_height); ``segmenter`` / ``flow_estimator`` name what made
    the masks and flow, with their options.
    """

    name: str
    frames: np.ndarray
    masks: np.ndarray
    flow_forward: np.ndarray
    flow_backward: np.ndarray
    occlusion_forward: np.ndarray
    occlusion_backward: np.ndarray
    fps: float
    source: dict[str, Any]
    source_indices: np.ndarray
    segmenter: dict[str, Any] = field(default_factory=dict)
    flow_estimator: dict[str, Any] = field(default_factory=dict)

    @property
    def boxes(self) -> np.ndarray:
        """(T, 4) int32 x, y, w, h of each mask; zeros where the mask is empty."""
        return boxes_of(self.masks)

    def validate(self) -> None:
        t, h, w = self.frames.shape[:3]
        if self.frames.dtype != np.uint8 or self.frames.shape != (t, h, w, 3):
            raise ValueError(
                f"frames must be (T, H, W, 3) uint8, got {self.frames.shape} {self.frames.dtype}"
            )
        if t < 2:
            raise ValueError("a stored video needs at least 2 frames")
        if self.masks.shape != (t, h, w):
            raise ValueError(f"masks {self.masks.shape} do not match frames {(t, h, w)}")
        for n in ("flow_forward", "flow_backward"):
            if getattr(self, n).shape != (t - 1, h, w, 2):
                raise ValueError(f"{n} {getattr(self, n).shape} should be {(t - 1, h, w, 2)}")
        for n in ("occlusion_forward", "occlusion_backward"):
            if getattr(self, n).shape != (t - 1, h, w):
                raise ValueError(f"{n} {getattr(self, n).shape} should be {(t - 1, h, w)}")
        if len(self.source_indices) != t:
            raise ValueError("source_indices needs one entry per frame")

    def summary(self) -> dict[str, Any]:
        """The index entry: what `video list` prints without opening the HDF5 file."""
        t, h, w = self.frames.shape[:3]
        cov = self.masks.reshape(t, -1).mean(1)
        return video_summary(
            self.name, (t, h, w), self.fps, cov, self.segmenter, self.flow_estimator, self.source
        )


def video_summary(
    name: str,
    shape: tuple[int, int, int],
    fps: float,
    coverage: np.ndarray,
    segmenter: dict[str, Any],
    flow_estimator: dict[str, Any],
    source: dict[str, Any],
) -> dict[str, Any]:
    """A video's index entry from its (T, H, W), rate, per-frame mask coverage and metadata."""
    t, h, w = shape
    cov = np.asarray(coverage, np.float64)
    return {
        "name": name,
        "frames": int(t),
        "fps": float(fps),
        "width": int(w),
        "height": int(h),
        "duration_s": round(t / fps, 3),
        "mask_coverage_mean": round(float(cov.mean()), 4),
        "empty_masks": int((cov == 0).sum()),
        "segmenter": str(segmenter.get("name", "")),
        "flow_estimator": str(flow_estimator.get("name", "")),
        "source": {
            "path": str(source.get("path", "")),
            "kind": str(source.get("kind", "")),
            "sha256": str(source.get("sha256", "")),
            **({"lens": dict(source["lens"])} if source.get("lens") else {}),
        },
    }


def boxes_of(masks: np.ndarray) -> np.ndarray:
    """(T, H, W) bool -> (T, 4) int32 x, y, w, h boxes (zeros for an empty mask)."""
    out = np.zeros((len(masks), 4), np.int32)
    for i, m in enumerate(masks):
        rows, cols = np.flatnonzero(m.any(1)), np.flatnonzero(m.any(0))
        if rows.size:
            out[i] = (cols[0], rows[0], cols[-1] - cols[0] + 1, rows[-1] - rows[0] + 1)
    return out


# -- the HDF5 file -----------------------------------------------------------------------------------


def _fill_video(f: Any, rec: VideoRecord) -> None:
    t, h, w = rec.frames.shape[:3]
    g = f.create_group("flow")
    # frames and flow take lzf: much faster to write than gzip for a few more bytes (BENCHMARKS.md, Video store)
    f.create_dataset("frames", data=rec.frames, chunks=(1, h, w, 3), compression="lzf")
    for key, arr in (("forward", rec.flow_forward), ("backward", rec.flow_backward)):
        g.create_dataset(
            key, data=arr.astype(np.float16), chunks=(1, h, w, 2), compression="lzf", shuffle=True
        )
    for key, arr in (
        ("occlusion_forward", rec.occlusion_forward),
        ("occlusion_backward", rec.occlusion_backward),
    ):
        g.create_dataset(
            key, data=arr.astype(np.uint8), chunks=(1, h, w), compression="gzip", compression_opts=_GZIP
        )
    _fill_rest(f, rec)


def _fill_rest(f: Any, rec: VideoRecord) -> None:
    """Attributes, masks and boxes: what is known only once the masks are."""
    t, h, w = rec.frames.shape[:3]
    f.attrs["zooctl_kind"] = "video"
    f.attrs["schema_version"] = FILE_VERSION
    f.attrs["name"] = rec.name
    f.attrs["fps"] = float(rec.fps)
    f.attrs["source"] = json.dumps(rec.source, sort_keys=True, default=str)
    f.attrs["segmenter"] = json.dumps(rec.segmenter, sort_keys=True, default=str)
    f.attrs["flow_estimator"] = json.dumps(rec.flow_estimator, sort_keys=True, default=str)
    f.create_dataset(
        "masks",
        data=rec.masks.astype(np.uint8),
        chunks=(1, h, w),
        compression="gzip",
        compression_opts=_GZIP,
    )
    f.create_dataset("boxes", data=rec.boxes)
    f.create_dataset("source_indices", data=np.asarray(rec.source_indices, np.int64))


class _KeepingFile(io.RawIOBase):
    """A file HDF5 writes through (h5py's file-object driver) that keeps the first write error
    instead of passing it to the library: HDF5 closing a file after a failed write (a full disk)
    can crash the process, so writes after the error are dropped and the owner raises it."""

    def __init__(self, path: Path) -> None:
        self._f = open(path, "w+b", buffering=0)
        self.error: OSError | None = None

    def readable(self) -> bool:
        return True

    def writable(self) -> bool:
        return True

    def seekable(self) -> bool:
        return True

    def seek(self, offset: int, whence: int = 0) -> int:
        return self._f.seek(offset, whence)

    def tell(self) -> int:
        return self._f.tell()

    def readinto(self, b) -> int:
        return self._f.readinto(b)

    def write(self, b) -> int:
        n = len(memoryview(b))
        if self.error is None:
            try:
                self._f.write(b)  # unbuffered: a short write raises or is retried by the driver
            except OSError as exc:
                self.error = exc
        return n

    def truncate(self, size: int | None = None) -> int:
        if self.error is None:
            try:
                return self._f.truncate(size)
            except OSError as exc:
                self.error = exc
        return self.tell() if size is None else size

    def close(self) -> None:
        super().close()
        self._f.close()


class VideoWriter:
    """A video's HDF5 file written as it is made, to a temporary beside its final path (the layout
    `VideoStore.add` writes): frames and flow a few at a time as they are decoded and computed, the
    masks once made, the attributes last; memory holds a few frames whatever the length.

    `VideoStore.add_written` publishes the finished file; ``discard()`` (safe to call again, and
    after a failure) closes and removes it. ``frames`` is the frames dataset for reading back.

    ``behind``: bytes of frames and flow that may wait in memory for a background thread to
    compress and write them (0: written at once, on the caller's thread). The thread runs at a
    lower priority and writes frames before flow, so that compressing the flow fills a core the
    flow or the segmenter leaves idle instead of holding them up; the arrays given are kept until
    written (the caller must not change them), a write error is raised by the next call.
    """

    def __init__(self, tmp: Path, size: tuple[int, int], behind: int = 0) -> None:
        import h5py

        self.path = Path(tmp)
        w, h = size
        self._what = f"writing {self.path}"
        self._io = _KeepingFile(self.path)
        self._t = 0
        self._pairs = 0
        self._masks: Any = None
        self._boxes: list[np.ndarray] = []
        self.coverage: list[float] = []
        self._behind = max(int(behind), 0)
        self._queue: dict[str, deque] = {"frames": deque(), "flow": deque()}
        self._waiting = 0  # bytes queued
        self._cv = threading.Condition()
        self._thread: threading.Thread | None = None
        self._failed: BaseException | None = None
        self._closing = False
        self._waiters = 0  # callers waiting for the writer thread
        with self._writing():
            self._f = f = h5py.File(self._io, "w")
            g = f.create_group("flow")

            def grow(group, key, shape, dtype, **filters):
                return group.create_dataset(
                    key,
                    shape=(0, *shape),
                    maxshape=(None, *shape),
                    dtype=dtype,
                    chunks=(1, *shape),
                    **filters,
                )

            # frames and flow take lzf: much faster to write than gzip for a few more bytes (BENCHMARKS.md, Video store)
            self._frames = grow(f, "frames", (h, w, 3), np.uint8, compression="lzf")
            flow = {"compression": "lzf", "shuffle": True}
            occ = {"compression": "gzip", "compression_opts": _GZIP}
            self._flow = [
                grow(g, "forward", (h, w, 2), np.float16, **flow),
                grow(g, "backward", (h, w, 2), np.float16, **flow),
                grow(g, "occlusion_forward", (h, w), np.uint8, **occ),
                grow(g, "occlusion_backward", (h, w), np.uint8, **occ),
            ]

    def __len__(self) -> int:
        return self._t

    @property
    def frames(self):
        """The frames dataset, once every frame given is written."""
        self._wait("frames")
        return self._frames

    def add_frames(self, frames: np.ndarray) -> None:
        """Append (N, H, W, 3) uint8 frames."""
        start, n = self._t, len(frames)

        def write() -> None:
            with self._writing():
                self._frames.resize(start + n, axis=0)
                self._frames[start : start + n] = frames

        self._t += n
        self._submit("frames", np.asarray(frames).nbytes, write)

    def add_flow(
        self, forward, backward, occlusion_forward=None, occlusion_backward=None, occlusion=None
    ) -> None:
        """Append the flow of the next N frame pairs ((N, H, W, 2) float, (N, H, W) bool).

        ``occlusion``: instead of the two occlusion arrays, ``occlusion(forward[k], backward[k]) ->
        (occlusion_forward[k], occlusion_backward[k])`` of one pair's float32 flow, made where the
        flow is written (on the writer thread, when writing behind)."""
        if occlusion is None and (occlusion_forward is None or occlusion_backward is None):
            raise ValueError("add_flow needs the occlusion arrays or a function that makes them")
        parts = (
            (forward, backward)
            if occlusion is not None
            else (forward, backward, occlusion_forward, occlusion_backward)
        )
        start, n = self._pairs, len(forward)
        nbytes = sum(np.asarray(p).nbytes for p in parts)
        if self._behind and self._waiting + nbytes > self._behind:
            parts, nbytes = self._spill(parts), 0  # no room in memory: it waits on disk

        def write() -> None:
            arrays = parts if occlusion is None else (*parts, *_occlusions(occlusion, *parts))
            with self._writing():
                for ds, arr in zip(self._flow, arrays):
                    ds.resize(start + n, axis=0)
                    for k in range(n):  # a pair at a time: HDF5 serves other callers in between
                        ds[start + k] = np.asarray(arr[k]).astype(ds.dtype, copy=False)
            for arr in parts:
                if hasattr(arr, "close"):
                    arr.close()

        self._pairs += n
        self._submit("flow", nbytes, write)

    # -- writing behind ----------------------------------------------------------------------------

    def _submit(self, kind: str, nbytes: int, write: Callable[[], None]) -> None:
        """Run ``write`` now, or queue it for the background thread (waiting while more than
        ``behind`` bytes are queued)."""
        if not self._behind:
            write()
            return
        with self._cv:
            self._waiters += 1
            try:
                while self._failed is None and self._waiting and self._waiting + nbytes > self._behind:
                    self._cv.wait()
            finally:
                self._waiters -= 1
            self._raise_failure()
            self._queue[kind].append((nbytes, write))
            self._waiting += nbytes
            if self._thread is None:
                self._thread = threading.Thread(target=self._write_behind, name="video-writer", daemon=True)
                self._thread.start()
            self._cv.notify_all()

    def _spill(self, parts) -> list[_Spilled]:
        """``parts`` copied to temporary files beside the video, to wait there for the writer
        thread instead of in memory."""
        with self._writing():
            return [_Spilled(np.asarray(p), self.path.parent) for p in parts]

    def _write_behind(self) -> None:
        base = thread_priority()
        low = base is not None and set_thread_priority(base + 10)
        while True:
            with self._cv:
                while not self._closing and not (self._queue["frames"] or self._queue["flow"]):
                    self._cv.wait()
                if self._closing:
                    return
                queue = self._queue["frames"] or self._queue["flow"]
                nbytes, write = queue[0]  # left queued until written: `_wait` sees it
                waited_on = self._waiters > 0
            # the caller waits for this thread: it then works at the caller's priority (a busy
            # machine would otherwise leave it the crumbs), and lower again once it is not waited on
            if base is not None and waited_on == low:
                low = set_thread_priority(base if waited_on else base + 10) and not waited_on
            try:
                write()
            except BaseException as exc:  # raised to the caller by its next call
                with self._cv:
                    self._failed = exc
                    for q in self._queue.values():
                        q.clear()
                    self._waiting = 0
                    self._cv.notify_all()
                return
            with self._cv:
                queue.popleft()
                self._waiting -= nbytes
                self._cv.notify_all()

    def _wait(self, *kinds: str) -> None:
        """Until what was given of ``kinds`` (default: everything) is written."""
        with self._cv:
            self._waiters += 1
            try:
                while self._failed is None and any(self._queue[k] for k in kinds or self._queue):
                    self._cv.wait()
            finally:
                self._waiters -= 1
            self._raise_failure()

    def _stop_writing(self) -> None:
        """End the background thread (after the write it is doing; what is still queued is dropped)."""
        with self._cv:
            self._closing = True
            self._cv.notify_all()
        if self._thread is not None:
            self._thread.join()
            self._thread = None

    def _raise_failure(self) -> None:
        if self._failed is not None:
            raise self._failed

    @property
    def masks(self):
        """The masks dataset (T, H, W) uint8 0/1: the frames `set_mask` has stored so far."""
        return self._masks

    def set_mask(self, i: int, mask: np.ndarray) -> None:
        """Store frame i's (H, W) bool mask; every frame's, in order 0, 1, ..."""
        if i != len(self._boxes):
            raise ValueError(f"masks are stored in order: expected frame {len(self._boxes)}, got {i}")
        with self._writing():
            if self._masks is None:
                _, h, w, _ = self._frames.shape
                self._masks = self._f.create_dataset(
                    "masks",
                    shape=(self._t, h, w),
                    dtype=np.uint8,
                    chunks=(1, h, w),
                    compression="gzip",
                    compression_opts=_GZIP,
                )
            self._masks[i] = mask
        self._boxes.append(boxes_of(mask[None])[0])
        self.coverage.append(float(mask.mean()))

    def finish(
        self, name: str, fps: float, source: dict, source_indices, segmenter: dict, flow_estimator: dict
    ):
        """Write the attributes and close the file; returns the video's index summary."""
        self._wait()
        self._stop_writing()
        t, h, w, _ = self._frames.shape
        if t < 2 or self._pairs != t - 1 or len(self._boxes) != t or len(source_indices) != t:
            raise ValueError(
                f"incomplete video file: {t} frames, {self._pairs} flow pairs, {len(self._boxes)} masks"
            )
        with self._writing():
            f = self._f
            f.attrs["zooctl_kind"] = "video"
            f.attrs["schema_version"] = FILE_VERSION
            f.attrs["name"] = name
            f.attrs["fps"] = float(fps)
            f.attrs["source"] = json.dumps(source, sort_keys=True, default=str)
            f.attrs["segmenter"] = json.dumps(segmenter, sort_keys=True, default=str)
            f.attrs["flow_estimator"] = json.dumps(flow_estimator, sort_keys=True, default=str)
            f.create_dataset("boxes", data=np.stack(self._boxes).astype(np.int32))
            f.create_dataset("source_indices", data=np.asarray(source_indices, np.int64))
            f.close()
            self._io.close()
        summary = video_summary(
            name, (t, h, w), fps, np.asarray(self.coverage), segmenter, flow_estimator, source
        )
        summary["bytes"] = self.path.stat().st_size
        return summary

    @contextlib.contextmanager
    def _writing(self) -> Iterator[None]:
        """A write failure, HDF5's or the one the file kept, as one clear `StoreError`."""
        with writing(self._what):
            try:
                yield
            except OSError as exc:
                raise self._io.error or exc from None
            if self._io.error is not None:
                raise self._io.error

    def discard(self) -> None:
        """Close and remove the temporary (whatever state it is in)."""
        self._stop_writing()
        with contextlib.suppress(Exception):
            if getattr(self, "_f", None):
                self._f.close()
        with contextlib.suppress(Exception):
            self._io.close()
        self.path.unlink(missing_ok=True)


def _occlusions(occlusion, forward, backward) -> tuple[np.ndarray, np.ndarray]:
    """(N, H, W) bool x2: ``occlusion`` of each pair of ``forward`` and ``backward``."""
    pairs = [
        occlusion(np.asarray(forward[k], np.float32), np.asarray(backward[k], np.float32))
        for k in range(len(forward))
    ]
    return np.stack([p[0] for p in pairs]), np.stack([p[1] for p in pairs])


class _Spilled:
    """An (N, ...) array waiting in an unlinked temporary file (gone once closed, or when the process
    ends), read back one record at a time."""

    def __init__(self, arr: np.ndarray, folder: Path) -> None:
        import tempfile

        self.dtype, self.shape = arr.dtype, arr.shape
        self._item = arr[0].nbytes if len(arr) else 0
        self._file = tempfile.TemporaryFile(prefix=".zooctl-spill-", dir=folder, buffering=0)
        try:
            data = memoryview(np.ascontiguousarray(arr)).cast("B")
            done = 0
            while done < len(data):
                done += self._file.write(data[done:])
        except BaseException:
            self._file.close()
            raise

    def __len__(self) -> int:
        return self.shape[0]

    def __getitem__(self, k: int) -> np.ndarray:
        buf = os.pread(self._file.fileno(), self._item, int(k) * self._item)
        if len(buf) != self._item:
            raise OSError(f"short read from a temporary file ({len(buf)} of {self._item} bytes)")
        return np.frombuffer(buf, self.dtype).reshape(self.shape[1:])

    def close(self) -> None:
        self._file.close()


def thread_priority() -> int | None:
    """The calling thread's nice value (Linux, where a thread has its own; elsewhere None)."""
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            return os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    return None


def set_thread_priority(nice: int) -> bool:
    """Set the calling thread's nice value (Linux); False where it may not (raising a thread's
    priority back needs the privilege to)."""
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), nice)
    except (OSError, AttributeError):
        return False
    return True


def lower_thread_priority(step: int) -> None:
    """Raise the calling thread's nice value by ``step`` (Linux, where a thread has its own; elsewhere
    nothing): work that is not waited for yet (writing the file behind, the network's looks while the
    tracker runs) then fills an idle core instead of slowing the work that is."""
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            tid = threading.get_native_id()
            os.setpriority(os.PRIO_PROCESS, tid, os.getpriority(os.PRIO_PROCESS, tid) + step)


def read_video_h5(path: Path, what: tuple[str, ...] = ("frames", "masks", "flow")) -> VideoRecord:
    """Read a stored video; leave out parts with ``what`` (missing parts come back as empty arrays)."""
    hint = "remove it with `zooctl video rm` and add it again"
    parts = ["source_indices", *(p for p in ("frames", "masks", "flow") if p in what)]
    return read_h5(path, "the video file", hint, lambda f: _read_video(f, path, what), parts)


def _read_video(f: Any, path: Path, what: tuple[str, ...]) -> VideoRecord:
    if f.attrs.get("zooctl_kind") != "video" or int(f.attrs.get("schema_version", -1)) != FILE_VERSION:
        raise StoreError(
            f"{path} is not a version-{FILE_VERSION} zooctl video file", hint="add the video again"
        )
    empty = np.zeros((0,), np.float32)
    fl = "flow" in what
    return VideoRecord(
        name=str(f.attrs["name"]),
        frames=f["frames"][()] if "frames" in what else np.zeros((0, 0, 0, 3), np.uint8),
        masks=f["masks"][()].astype(bool) if "masks" in what else np.zeros((0, 0, 0), bool),
        flow_forward=f["flow/forward"].astype(np.float32)[()] if fl else empty,  # no float16 copy held
        flow_backward=f["flow/backward"].astype(np.float32)[()] if fl else empty,
        occlusion_forward=f["flow/occlusion_forward"][()].astype(bool) if fl else empty,
        occlusion_backward=f["flow/occlusion_backward"][()].astype(bool) if fl else empty,
        fps=float(f.attrs["fps"]),
        source=json.loads(f.attrs["source"]),
        source_indices=f["source_indices"][()],
        segmenter=json.loads(f.attrs["segmenter"]),
        flow_estimator=json.loads(f.attrs["flow_estimator"]),
    )


# -- the store -------------------------------------------------------------------------------------


class VideoStore(IndexedStore):
    """The preprocessed videos of one store root."""

    noun, article, place, list_cmd = "video", "a", "the store", "zooctl video list"
    key, label, repair_cmd = "videos", "video index", "zooctl video repair"
    folder = "videos"
    required = {
        "name": str,
        "frames": int,
        "fps": (int, float),
        "width": int,
        "height": int,
        "duration_s": (int, float),
        "mask_coverage_mean": (int, float),
        "empty_masks": int,
        "segmenter": str,
        "flow_estimator": str,
        "source": dict,
        "bytes": int,
    }

    def check_entry(self, name: str, entry: Any) -> str | None:
        problem = super().check_entry(name, entry)
        if problem is None and not all(
            isinstance(entry["source"].get(k), str) for k in ("path", "kind", "sha256")
        ):
            return "has a bad 'source'"
        return problem

    def path(self, name: str) -> Path:
        return self.dir / f"{name}.h5"

    def cache_dir(self, name: str) -> Path:
        """Derived data of one video (retrieval's query embeddings): dropped with the video."""
        return self.dir / f"{name}.cache"

    def read_some(self, name: str, pick: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Read only the frames ``pick(boxes (T, 4) x, y, w, h; zeros: empty mask) -> indices`` chooses.

        Returns the sorted indices (K,), frames (K, H, W, 3) uint8 and masks (K, H, W) bool.
        Frames are stored one per chunk, so this decodes K frames, not T.
        """
        self.summary(name)
        hint = "remove it with `zooctl video rm` and add it again"
        try:
            with open_h5(self.path(name), "the video file", hint, ["boxes"]) as f:
                fd, md = f["frames"], f["masks"]
                _check_frames_masks(self.path(name), fd.shape, md.shape, f["boxes"].shape, hint)
                idx = np.unique(np.asarray(pick(f["boxes"][()]), np.int64))
                frame_bytes = math.prod(fd.shape[1:]) * fd.dtype.itemsize + math.prod(md.shape[1:])
                what = f"the video file {self.path(name)}: {len(idx)} of its frames declare"
                check_read(what, len(idx) * frame_bytes, "max_array_mb", StoreError)
                if len(idx) == 0:
                    _, h, w, _ = fd.shape
                    return idx, np.zeros((0, h, w, 3), np.uint8), np.zeros((0, h, w), bool)
                # One read per frame: h5py's point selection over chunked, compressed data is
                # much slower than plain reads of whole chunks (BENCHMARKS.md, Retrieval).
                return (
                    idx,
                    np.stack([fd[int(i)] for i in idx]),
                    np.stack([md[int(i)] for i in idx]).astype(bool),
                )
        except (OSError, KeyError, ValueError, TypeError, IndexError) as exc:
            raise StoreError(f"the video file {self.path(name)} is unreadable: {exc}", hint=hint) from None

    def get(self, name: str, what: tuple[str, ...] = ("frames", "masks", "flow")) -> VideoRecord:
        """Load a stored video (only the parts in ``what``). Raises `NotFoundError` for an unknown name."""
        self.summary(name)
        return read_video_h5(self.path(name), what)

    # -- writing ---------------------------------------------------------------------------------
    def check_new(self, name: str, replace: bool = False) -> str:
        """Fail early (before minutes of preprocessing) on a bad or taken name."""
        check_name(name, "video name")
        if not replace and self.exists(name):
            raise self.exists_error(name)
        return name

    def begin_file(self, name: str, size: tuple[int, int], behind: int = 0) -> VideoWriter:
        """A `VideoWriter` for a new video ``name`` of frames ``size`` (w, h), on a temporary beside
        its final path (``behind``: `VideoWriter`'s); publish it with `add_written`, or ``discard()`` it."""
        return VideoWriter(temp_path(self.path(name)), size, behind)

    def add_written(
        self, name: str, writer: VideoWriter, summary: dict[str, Any], replace: bool = False
    ) -> None:
        """Publish a finished `VideoWriter`'s file as ``name`` with its index entry, atomically
        (under the store's lock the name is checked again); the temporary is gone afterwards."""
        check_name(name, "video name")
        self.publish_written(name, summary, [(writer.path, self.path(name))], replace)

    def add(self, rec: VideoRecord, replace: bool = False) -> dict[str, Any]:
        """Store a video held in memory atomically; returns its index summary (`video add` streams
        into `begin_file` instead)."""
        name = self.check_new(rec.name, replace)
        rec.validate()
        image = h5_image(lambda f: _fill_video(f, rec))
        summary = rec.summary()
        summary["bytes"] = len(image)
        self.publish_item(name, summary, [(self.path(name), image)], replace)
        return summary

    def add_file(self, name: str, data: bytes, summary: dict[str, Any], replace: bool = False) -> None:
        """Store a video file made elsewhere (a batch worker's `add_video` into its own store),
        given as its bytes and its index ``summary``, under ``name`` (renamed inside when the
        worker stored it under another), atomically like `add_written`."""
        import h5py

        check_name(name, "video name")
        tmp = temp_path(self.path(name))
        try:
            with writing(f"adding video {name!r}"):
                tmp.write_bytes(data)
            with h5py.File(tmp, "r+") as f:
                if f.attrs.get("name") != name:
                    f.attrs["name"] = name
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise
        summary = {**summary, "name": name, "bytes": tmp.stat().st_size}
        self.publish_written(name, summary, [(tmp, self.path(name))], replace)

    def remove_side_data(self, name: str) -> None:
        shutil.rmtree(self.cache_dir(name), ignore_errors=True)  # query embeddings of the old video

    def remove_files(self, name: str) -> None:
        self.path(name).unlink(missing_ok=True)
        self.remove_side_data(name)

    def remove_leftovers(self, keep: set[str]) -> tuple[int, int]:
        """Query caches of videos that are gone."""
        orphans = 0
        if self.dir.is_dir():
            for p in self.dir.glob("*.cache"):
                if p.is_dir() and p.name[: -len(".cache")] not in keep:
                    shutil.rmtree(p, ignore_errors=True)
                    orphans += 1
        return 0, orphans

    def rebuild_entry(
        self, name: str, path: Path, old: dict[str, Any] | None
    ) -> tuple[dict[str, Any], list[str]]:
        from .video_reader import StoredVideo

        with StoredVideo(path) as sv:  # a frame at a time: a long video's arrays never sit in memory
            t, h, w = sv.frames.shape[:3]
            if t < 2:
                raise StoreError(f"the video in {path.name} is invalid: it has {t} frame(s), not 2 or more")
            if sv.name != name:
                raise StoreError(f"{path.name} holds a video named {sv.name!r}")
            coverage = np.concatenate([m.reshape(len(m), -1).mean(1) for _, m in sv.masks.chunks()])
            summary = video_summary(
                name, (t, h, w), sv.fps, coverage, sv.segmenter, sv.flow_estimator, sv.source
            )
        summary["bytes"] = path.stat().st_size
        return summary, []


def _check_frames_masks(path: Path, frames: tuple, masks: tuple, boxes: tuple, hint: str) -> None:
    """A `StoreError` unless a video file's frames (T, H, W, 3), masks (T, H, W) and boxes (T, 4)
    agree: a damaged file with fewer masks than frames is one clear line, not an IndexError."""
    if len(frames) != 4 or frames[3] != 3:
        why = f"its frames are {frames}, not (T, H, W, 3)"
    elif tuple(masks) != tuple(frames[:3]):
        why = f"it has masks {tuple(masks)} for frames {tuple(frames[:3])}"
    elif tuple(boxes) != (frames[0], 4):
        why = f"it has boxes {tuple(boxes)} for {frames[0]} frames"
    else:
        return
    raise StoreError(f"the video file {path} is damaged: {why}", hint=hint)
