"""What a fit reads: frames, masks, optical flow, optional intrinsics and ground truth.

Sources (`load_fit_video`):

- a benchmark video folder made by `zooctl bench make` (``video.npz`` inside): frames, masks,
  flow and occlusion, intrinsics, and the ground truth the metrics need;
- a DAVIS-style folder (``JPEGImages/`` + ``Annotations/``), a folder of images or a video file,
  decoded by `zooctl.video.decode`; masks from DAVIS annotations, from ``--masks DIR`` (one image
  per frame, non-zero = animal) or, with ``--masks auto``, from the GrabCut segmenter.

Flow is computed with DIS (`zooctl.video.flow`) on the fit-resolution frames when the source
has none: the losses only ever see the fit resolution.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import InputError, UsageError
from ..geometry import mask_chunks, nonempty_frames

if TYPE_CHECKING:
    from ..store.video_reader import FrameArray


@dataclass
class FitVideo:
    """A video ready to fit.

    frames (T, H, W, 3) uint8; masks (T, H, W) bool; flow (T-1, H, W, 2) float32 forward flow in
    pixels of this resolution or None; flow_valid (T-1, H, W) bool; intrinsics (4,) fx, fy, cx, cy
    in pixels of this resolution or None; gt: ground truth arrays (benchmark videos only);
    camera_rotations (T, 3, 3) world-to-camera rotations (OpenCV axes) when the camera's motion is
    known (``--cameras``, or `zooctl bench run --known-camera`), else None; lens: the lens a stored
    video was filmed with (`zooctl.video.lens.read_lens`'s dict), when known; animal_check: a stored
    video's check that its automatic masks hold an animal (`zooctl.video.animal_check`), when made.

    A stored video's frames, masks, flow and flow_valid are `FrameArray` s: read from its file as
    they are indexed, so a long video's frames, masks and flow never sit in memory whole (what needs
    every mask, `crop_box`, `MaskWindow`, `nonempty_frames`, reads them a chunk at a time).
    ``cache`` keeps what the fit derives from them (the flow at the fit resolution) for the next
    fit of the same video (the template trials).
    """

    name: str
    frames: np.ndarray | FrameArray
    masks: np.ndarray | FrameArray
    fps: float = 30.0
    flow: np.ndarray | FrameArray | None = None
    flow_valid: np.ndarray | FrameArray | None = None
    intrinsics: np.ndarray | None = None
    gt: dict[str, Any] = field(default_factory=dict)
    source: str = ""
    mask_source: str = "given"
    camera_rotations: np.ndarray | None = None
    lens: dict[str, Any] | None = None
    animal_check: dict[str, Any] | None = None
    cache: dict[Any, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def num_frames(self) -> int:
        return int(self.frames.shape[0])

    @property
    def size(self) -> tuple[int, int]:
        """(H, W)."""
        return int(self.frames.shape[1]), int(self.frames.shape[2])

    def check(self) -> FitVideo:
        T = self.num_frames
        if T == 0:
            raise InputError(f"video {self.name!r} has no frames")
        if self.masks.shape != self.frames.shape[:3]:
            raise InputError(
                f"video {self.name!r}: {self.masks.shape[0]} masks of size {self.masks.shape[1:]} for "
                f"{T} frames of size {self.frames.shape[1:3]}",
                hint="give one mask per frame, the size of the frames",
            )
        if not len(nonempty_frames(self.masks)):
            raise InputError(
                f"video {self.name!r}: every mask is empty, there is no animal to fit",
                hint="check the masks (non-zero pixels mark the animal)",
            )
        return self

    def close(self) -> None:
        """Close the stored video file its arrays read (nothing for arrays in memory); they, and
        every part of this video, cannot be read after."""
        for a in (self.frames, self.masks, self.flow, self.flow_valid):
            if hasattr(a, "close"):
                a.close()

    def truncated(self, max_frames: int | None) -> FitVideo:
        if max_frames is None or max_frames >= self.num_frames:
            return self
        return self.part(0, max_frames)

    def part(self, start: int, stop: int) -> FitVideo:
        """Frames ``start`` to ``stop`` (and the flow between them) as a video of their own; a
        stored video's stay unread."""
        return FitVideo(
            self.name,
            _part(self.frames, start, stop),
            _part(self.masks, start, stop),
            self.fps,
            None if self.flow is None else _part(self.flow, start, max(stop - 1, start)),
            None if self.flow_valid is None else _part(self.flow_valid, start, max(stop - 1, start)),
            self.intrinsics,
            {k: _part_gt(k, v, start, stop) for k, v in self.gt.items()},
            self.source,
            self.mask_source,
            None if self.camera_rotations is None else self.camera_rotations[start:stop],
            self.lens,
            self.animal_check,
        )


# The side (px) of the square an animal's mask fills below which the fit's outputs carry a note:
# a quarter of the fast preset's 128 px fit image, where a leg is a pixel or two wide.
SMALL_ANIMAL_SIDE = 32


def mask_areas(masks: Any) -> np.ndarray:
    """(T,) int64 pixels of each frame's mask, for (T, H, W) masks (an array or a `FrameArray`,
    read a chunk at a time)."""
    found = [np.zeros(0, np.int64)] + [b.reshape(len(b), -1).sum(1) for b in mask_chunks(masks)]
    return np.concatenate(found).astype(np.int64)


def mask_notes(masks: Any, side: int = SMALL_ANIMAL_SIDE) -> list[str]:
    """The fit record's notes on its masks: frames where they hold no animal, and an animal that
    fills less than a ``side`` x ``side`` square on average where they hold one (too few pixels to
    tell its shape, or specks a segmenter took for an animal)."""
    area = mask_areas(masks)
    held = area[area > 0]
    notes = []
    if 0 < len(held) < len(area):
        notes.append(
            f"the masks hold no animal on {len(area) - len(held)} of {len(area)} frames: only the "
            "smoothness terms pose the character there; check overlay.mp4, and give --box around "
            "the animal or your own --masks where it was in view"
        )
    if len(held) and held.mean() < side * side:
        notes.append(
            f"the masks cover {held.mean():.0f} pixels a frame on average (a square of "
            f"{held.mean() ** 0.5:.0f} px): too few to tell the animal's shape, or specks the "
            "segmenter took for an animal; check overlay.mp4, and film the animal closer, give --box "
            "around it or your own --masks"
        )
    return notes


def _part(a: Any, start: int, stop: int) -> Any:
    """Frames ``start`` to ``stop`` of an array, or of a stored video's `FrameArray` (left unread)."""
    return a.part(start, stop) if hasattr(a, "part") else a[start:stop]


_PER_FRAME_GT = {"vertices", "joints", "cam_rotation", "cam_translation", "input_masks"}
_PER_VIEW_FRAME_GT = {"view_masks", "view_rotation", "view_translation"}  # (C, T, ...)


def _part_gt(key: str, value: Any, start: int, stop: int) -> Any:
    if key in _PER_FRAME_GT:
        return value[start:stop]
    return value[:, start:stop] if key in _PER_VIEW_FRAME_GT else value


def load_fit_video(
    source: str | Path, masks: str | None = None, max_frames: int | None = None, max_size: int = 480
) -> FitVideo:
    """Read ``source`` (see the module docstring) into a checked `FitVideo`."""
    path = Path(source).expanduser()
    if not path.exists():
        raise InputError(
            f"{source} is neither a file nor a folder",
            hint="give a video file, a DAVIS-style folder, an image folder or a `bench make` video folder",
        )
    if path.is_dir() and (path / "video.npz").is_file():
        vid = load_bench_video(path)
        if masks is not None:
            raise UsageError("--masks cannot replace the masks of a benchmark video")
        return vid.truncated(max_frames).check()
    from ..video.decode import decode

    dec = decode(path, max_frames=max_frames, max_size=max_size)
    frames = dec.frames
    name = path.stem if path.is_file() else path.name
    if masks is None and dec.annotations is not None:
        m = _read_mask_folder(dec.annotations, dec.source_indices, frames.shape[1:3])
        src = "davis"
    elif masks is None:
        raise UsageError(
            f"{path.name} comes without masks",
            hint="give --masks DIR (one image per frame) or --masks auto (GrabCut segmentation)",
        )
    elif masks == "auto":
        m = auto_masks(frames)
        src = "auto"
    else:
        mdir = Path(masks).expanduser()
        if not mdir.is_dir():
            raise InputError(f"--masks {masks}: not a folder", hint="give a folder of mask images, or 'auto'")
        m = _read_mask_folder(mdir, dec.source_indices, frames.shape[1:3])
        src = "given"
    return FitVideo(name, frames, m, float(dec.fps), source=str(path), mask_source=src).check()


def _read_mask_folder(folder: Path, indices: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    from PIL import Image

    from ..video.decode import image_files
    from ..video.images import open_image

    files = image_files(folder)
    if len(files) == 0:
        raise InputError(f"{folder} holds no mask images")
    H, W = size
    out = np.zeros((len(indices), H, W), bool)
    for n, i in enumerate(indices):
        if i >= len(files):
            raise InputError(
                f"{folder} has {len(files)} masks, the video needs {int(indices.max()) + 1}",
                hint="give one mask per frame",
            )
        with open_image(files[i]) as im:
            a = np.asarray(im.convert("L").resize((W, H), Image.Resampling.NEAREST))
        out[n] = a > 0
    return out


def auto_masks(frames: np.ndarray) -> np.ndarray:
    """(T, H, W) bool masks from the built-in GrabCut segmenter (needs at least 2 frames)."""
    from ..video.grabcut import GrabCutTracker

    return GrabCutTracker().segment(frames)


# -- benchmark videos ---------------------------------------------------------------------------


def bench_meta(folder: Path) -> dict[str, Any]:
    """A benchmark video's ``meta.json`` (`zooctl.benchdata.make.make_video`), {} where it has
    none; an unreadable one is an `InputError` naming it."""
    import json

    path = folder / "meta.json"
    if not path.is_file():
        return {}
    try:
        meta = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"{path} is unreadable: {exc}", hint="re-run `zooctl bench make`") from None
    if not isinstance(meta, dict):
        raise InputError(f"{path} is not a JSON object", hint="re-run `zooctl bench make`")
    return meta


def load_bench_video(folder: Path) -> FitVideo:
    """A folder written by `zooctl.benchdata.make.make_video` (``video.npz`` + ``meta.json``)."""
    try:
        with np.load(folder / "video.npz") as z:
            data = {k: z[k] for k in z.files}
    except (OSError, ValueError) as exc:
        raise InputError(
            f"{folder}/video.npz is unreadable: {exc}", hint="re-run `zooctl bench make`"
        ) from None
    meta = bench_meta(folder)
    need = ("frames", "masks")
    for k in need:
        if k not in data:
            raise InputError(f"{folder}/video.npz has no {k!r}", hint="re-run `zooctl bench make`")
    gt = {k[3:]: v for k, v in data.items() if k.startswith("gt_")}
    gt["meta"] = meta
    return FitVideo(
        meta.get("name", folder.name),
        data["frames"],
        data["masks"].astype(bool),
        float(meta.get("fps", 30.0)),
        data.get("flow"),
        data.get("flow_valid"),
        data.get("intrinsics"),
        gt,
        str(folder),
        "given",
    )


# -- resampling to the fit resolution ----------------------------------------------------------


def fit_resolution(H: int, W: int, longest: int) -> tuple[int, int, float]:
    """(h, w, s): the fit image size with the longest side ``longest`` and the scale s = h / H."""
    s = min(1.0, longest / max(H, W))
    return max(8, round(H * s)), max(8, round(W * s)), s


def resample_masks(masks: Any, h: int, w: int) -> np.ndarray:
    """(T, H, W) bool (an array, a `FrameArray` or a `MaskWindow`, iterated a frame at a time)
    -> (T, h, w) float32 coverage in [0, 1] (area averaging)."""
    import cv2

    out = np.empty((len(masks), h, w), np.float32)
    for t, m in enumerate(masks):
        out[t] = cv2.resize(m.astype(np.float32), (w, h), interpolation=cv2.INTER_AREA)
    return out


class MaskWindow:
    """The (x0, y0, x1, y1) ``box`` window of (T, H, W) bool masks, an array or a stored video's
    `FrameArray`: (T, y1 - y0, x1 - x0), read a chunk at a time as it is iterated, a frame at a
    time as it is indexed, so the window of a long video is never held whole."""

    def __init__(self, masks: np.ndarray | FrameArray, box: tuple[int, int, int, int]) -> None:
        self.masks, self.box = masks, box

    @property
    def shape(self) -> tuple[int, int, int]:
        x0, y0, x1, y1 = self.box
        return len(self.masks), y1 - y0, x1 - x0

    def __len__(self) -> int:
        return len(self.masks)

    def __iter__(self) -> Iterator[np.ndarray]:
        x0, y0, x1, y1 = self.box
        for block in mask_chunks(self.masks):
            yield from block[:, y0:y1, x0:x1]

    def __getitem__(self, key: Any) -> np.ndarray:
        x0, y0, x1, y1 = self.box
        return np.asarray(self.masks[key], dtype=bool)[..., y0:y1, x0:x1]


def crop_box(masks: np.ndarray, margin: float = 0.15) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1): the union of every mask's box grown by ``margin`` of its size, in the image.

    The fit only looks at this window (the camera stays the full image's: the crop just moves
    the principal point), so a small animal in a large frame gets the fit's full resolution.
    """
    T, H, W = masks.shape
    seen = np.zeros((H, W), bool)
    for b in mask_chunks(masks):
        seen |= b.any(0)
    ys, xs = np.nonzero(seen)
    if len(xs) == 0:
        return 0, 0, W, H
    x0, x1, y0, y1 = xs.min(), xs.max() + 1, ys.min(), ys.max() + 1
    side = max(x1 - x0, y1 - y0)
    mx = my = margin * side
    return (
        max(0, int(x0 - mx)),
        max(0, int(y0 - my)),
        min(W, int(np.ceil(x1 + mx))),
        min(H, int(np.ceil(y1 + my))),
    )


def resample_flow(
    video: FitVideo, h: int, w: int, box: tuple[int, int, int, int] | None = None
) -> tuple[np.ndarray, np.ndarray] | None:
    """Forward flow (T-1, h, w, 2) in fit pixels and its validity (T-1, h, w) bool, or None (T = 1).

    Uses the video's own flow when it has some (read a chunk of frames at a time, cropped to
    ``box``), otherwise DIS on the downscaled frames with a forward-backward consistency check.
    The result is kept in ``video.cache`` for the next fit of the same video (the losses only
    read it: one copy serves every fit).
    """
    T, H, W = video.frames.shape[:3]
    if T < 2:
        return None
    x0, y0, x1, y1 = box if box is not None else (0, 0, W, H)
    key = ("flow", h, w, x0, y0, x1, y1)
    if key not in video.cache:
        video.cache[key] = _resample_flow(video, h, w, (x0, y0, x1, y1))
    return video.cache[key]


def _resample_flow(
    video: FitVideo, h: int, w: int, box: tuple[int, int, int, int]
) -> tuple[np.ndarray, np.ndarray]:
    import cv2

    x0, y0, x1, y1 = box
    H, W = y1 - y0, x1 - x0
    if video.flow is not None:
        sx, sy = w / W, h / H
        n = len(video.flow)
        flow = np.empty((n, h, w, 2), np.float32)
        valid = np.empty((n, h, w), bool)
        step = 16
        for s in range(0, n, step):
            e = min(s + step, n)
            fl = video.flow[s:e, y0:y1, x0:x1]
            ok = (
                np.ones(fl.shape[:3], bool)
                if video.flow_valid is None
                else np.asarray(video.flow_valid[s:e, y0:y1, x0:x1], bool)
            )
            for k, (f, v) in enumerate(zip(fl, ok, strict=True)):
                # Valid-weighted area average: background zeros must not shrink the flow at the edges.
                wsum = cv2.resize(v.astype(np.float32), (w, h), interpolation=cv2.INTER_AREA)
                fsum = cv2.resize(f.astype(np.float32) * v[..., None], (w, h), interpolation=cv2.INTER_AREA)
                flow[s + k] = fsum / np.maximum(wsum, 1e-6)[..., None] * np.array([sx, sy], np.float32)
                valid[s + k] = wsum > 0.5
        return flow, valid
    from ..video.flow import DISFlow, compute_video_flow

    small = np.stack(
        [
            cv2.resize(np.ascontiguousarray(f[y0:y1, x0:x1]), (w, h), interpolation=cv2.INTER_AREA)
            for f in video.frames
        ]
    )
    vf = compute_video_flow(DISFlow("medium"), small)
    return vf.forward.astype(np.float32), ~vf.occlusion_forward


# -- known cameras -----------------------------------------------------------------------------


def load_camera_rotations(spec: str, video: FitVideo) -> np.ndarray:
    """(T, 3, 3) known world-to-camera rotations for ``video`` (OpenCV axes: x right, y down,
    z forward). ``spec``: ``gt`` for a benchmark video's own cameras, or a ``.npz`` / ``.json``
    file holding ``rotations`` (T, 3, 3) (more frames than the video: the first T are used)."""
    import json

    T = video.num_frames
    if spec == "gt":
        if "cam_rotation" not in video.gt:
            raise UsageError(
                f"video {video.name!r} has no ground-truth cameras",
                hint="`--cameras gt` is for `zooctl bench make` videos; give a .npz or .json file",
            )
        rots = np.asarray(video.gt["cam_rotation"], np.float64)
    else:
        path = Path(spec).expanduser()
        if not path.is_file():
            raise InputError(
                f"camera file {spec} does not exist", hint="give a .npz or .json with `rotations`"
            )
        try:
            if path.suffix.lower() == ".json":
                rots = np.asarray(json.loads(path.read_text())["rotations"], np.float64)
            else:
                with np.load(path) as z:
                    rots = np.asarray(z["rotations"], np.float64)
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise InputError(
                f"camera file {spec} is unreadable ({type(exc).__name__}: {exc})",
                hint="a .npz or .json with `rotations`: (frames, 3, 3) world-to-camera rotations",
            ) from None
    if rots.ndim != 3 or rots.shape[1:] != (3, 3) or len(rots) < T:
        raise InputError(
            f"camera rotations of shape {tuple(rots.shape)} for a video of {T} frames",
            hint="give one (3, 3) world-to-camera rotation per frame",
        )
    rots = rots[:T]
    eye = np.einsum("tij,tkj->tik", rots, rots)
    if not np.isfinite(rots).all() or np.abs(eye - np.eye(3)).max() > 1e-3 or (np.linalg.det(rots) < 0).any():
        raise InputError(
            "the camera rotations are not all rotation matrices (orthonormal, determinant +1)",
            hint="give world-to-camera rotations, OpenCV axes (x right, y down, z forward)",
        )
    return rots
