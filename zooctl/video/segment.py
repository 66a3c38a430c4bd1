"""Segmenters: the user's own masks, and a learned model run from a local ONNX file.

Every segmenter has ``segment(frames, box=None, progress=None) -> (T, H, W) bool`` for frames
(T, H, W, 3) uint8 RGB. The classical automatic one is `zooctl.video.grabcut.GrabCutTracker`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import cv2
import numpy as np

from ..errors import InputError, MissingDependencyError, UsageError
from ..files import regular_size
from .decode import IMAGE_SUFFIXES, VIDEO_SUFFIXES, image_files
from .scratch import ScratchArray, working

Progress = Callable[[int, int], None]


def mask_from_image(img: np.ndarray, mode: str, where: str = "mask") -> np.ndarray:
    """A mask image -> (H, W) bool. Palette images: index != 0; with alpha: alpha > 127; else grey > 127
    (or > 0 when the file holds only 0/1 values). A photo (many colours) is an InputError."""
    a = np.asarray(img)
    if mode == "P":
        return a != 0
    check_mask_like(a, where)
    if a.ndim == 3 and a.shape[2] in (2, 4) and (a[..., -1] < 255).any():
        return a[..., -1] > 127
    grey = a if a.ndim == 2 else a[..., : min(3, a.shape[2])].max(-1)
    return grey > (0 if grey.max() <= 1 else 127)


def check_mask_like(a: np.ndarray, where: str) -> None:
    """InputError unless ``a`` (H, W[, C]) uint8 looks like a mask: a few flat colours, not a photo.

    Coarse colours (8 levels a channel, so compression noise at edges stays in its level): in a mask
    the four commonest cover nearly every pixel; in a photo they rarely reach half.
    """
    if not _mask_like(a):
        raise _not_a_mask(where)


def _not_a_mask(where: str) -> InputError:
    return InputError(
        f"{where} is not a mask: it has the many colours of a photo or video frame",
        hint="--masks takes single-channel or binary images (animal white or non-zero, background black)",
    )


def _mask_like(a: np.ndarray) -> bool:
    q = (np.asarray(a)[..., :3] if a.ndim == 3 else np.asarray(a)).astype(np.int64) // 32
    codes = q if q.ndim == 2 else (q[..., 0] * 8 + q[..., 1]) * 8 + q[..., 2]
    counts = np.sort(np.bincount(codes.ravel(), minlength=512))[::-1]
    return bool(counts[:4].sum() >= 0.9 * codes.size)


class MaskSegmenter:
    """User-supplied masks: a folder of mask images (PNG...) or a mask video, one per source frame.

    Matching: as many masks as stored frames (taken in order), or as many as the source has
    frames (``source_frames``; then the stored frames' ``source_indices`` pick theirs); any other
    count is an error. Size: the source's original size or the stored size; masks are resized to
    the stored size. Images or video frames with a photo's colours are refused.
    """

    name = "masks"

    def __init__(
        self,
        path: str | Path,
        source_indices: Sequence[int] | None = None,
        original_size: tuple[int, int] | None = None,
        source_frames: int | None = None,
        source_exact: bool = True,
    ) -> None:
        self.path = Path(path).expanduser()
        self.source_frames = source_frames
        self.source_exact = source_exact
        if not self.path.exists():
            raise InputError(
                f"mask source {self.path} does not exist", hint="give a folder of mask images or a mask video"
            )
        if not self.path.is_dir():
            regular_size(self.path, "mask source", None)  # a FIFO or a device would block or never end
        self.source_indices = None if source_indices is None else np.asarray(source_indices, dtype=np.int64)
        self.original_size = original_size

    def segment(self, frames: np.ndarray, box=None, progress: Progress | None = None) -> np.ndarray:
        t, h, w = frames.shape[:3]
        self._like = frames  # masks in memory for frames in memory, else in a scratch file
        if self.path.is_dir():
            return self._from_folder(t, h, w, progress)
        if self.path.suffix.lower() in VIDEO_SUFFIXES:
            return self._from_video(t, h, w, progress)
        raise InputError(
            f"{self.path.name} is neither a folder of masks nor a mask video",
            hint=f"give a folder of {'/'.join(IMAGE_SUFFIXES)} images or a {' '.join(VIDEO_SUFFIXES)} video",
        )

    def _pick(self, count: int, t: int) -> np.ndarray:
        """Which of ``count`` masks each of the ``t`` stored frames takes. A folder's frame count is
        exact (``source_exact``); a video file's header count may be off by a frame."""
        if count == t:
            return np.arange(t)
        src = self.source_frames
        slack = 0 if self.source_exact else 1
        if (
            self.source_indices is not None
            and count > int(self.source_indices.max())
            and (src is None or abs(count - src) <= slack)
        ):
            return self.source_indices
        of_source = f" (its source has {src})" if src is not None and src != t else ""
        raise InputError(
            f"{count} masks in {self.path} for a video of {t} frames{of_source}",
            hint="give exactly one mask per frame (in the same order as the frames)",
        )

    def _fit(self, mask: np.ndarray, h: int, w: int, where: str) -> np.ndarray:
        mh, mw = mask.shape
        allowed = {(w, h)} | ({tuple(self.original_size)} if self.original_size else set())
        if (mw, mh) not in allowed:
            sizes = " or ".join(f"{a}x{b}" for a, b in sorted(allowed))
            raise InputError(
                f"mask {where} is {mw}x{mh}, the frames are {sizes}",
                hint="masks must have the video's frame size",
            )
        if (mw, mh) != (w, h):
            mask = cv2.resize(mask.astype(np.float32), (w, h), interpolation=cv2.INTER_AREA) > 0.5
        return mask

    def _from_folder(self, t, h, w, progress) -> np.ndarray:
        from .images import open_image

        folder = self.path / "Annotations" if (self.path / "Annotations").is_dir() else self.path
        files = image_files(folder)
        if not files:
            raise InputError(
                f"{folder} holds no mask images",
                hint=f"masks are image files ({' '.join(IMAGE_SUFFIXES)}), one per frame",
            )
        pick = self._pick(len(files), t)
        out = working(self._like, t, (h, w), bool)
        for k, i in enumerate(pick):
            try:
                with open_image(files[i]) as im:
                    im.load()
                    m = mask_from_image(np.asarray(im), im.mode, files[i].name)
            except OSError as exc:
                raise InputError(f"{files[i]} is not a readable mask image: {exc}") from None
            out[k] = self._fit(m, h, w, files[i].name)
            if progress:
                progress(k + 1, t)
        return out

    def _from_video(self, t, h, w, progress) -> np.ndarray:
        from .decode import open_video

        # Enough masks to tell every count `_pick` accepts from those it refuses, and no more: a
        # long mask video is not read to its end.
        idx, src = self.source_indices, self.source_frames
        cap = max(t, int(idx.max()) + 1 if idx is not None and len(idx) else 0, (src or 0) + 1) + 1
        stream = open_video(self.path, max_size=None, max_frames=cap)
        # one pass over the mask video: its masks, at the stored size as they are decoded (4K ones
        # would take 8 MB a frame), wait in a scratch file, unless the frames are in memory anyway
        lazy = not isinstance(self._like, np.ndarray)
        masks: list[np.ndarray] | ScratchArray = ScratchArray(0, (h, w), bool) if lazy else []
        middle = (stream.total or 0) // 2  # a file's header count: about the middle
        for n, frame in enumerate(stream):
            if n == middle:  # on about 250k of its pixels: all of a 4K frame take 270 MB to count
                step = int(np.ceil((frame.shape[0] * frame.shape[1] / 250_000) ** 0.5))
                check_mask_like(frame[::step, ::step], f"the middle frame of {self.path.name}")
            masks.append(self._fit(frame.max(-1) > 127, h, w, f"frame {n} of {self.path.name}"))
        if len(masks) == cap and src is not None:
            raise InputError(
                f"over {cap - 1} masks in {self.path} for a video of {t} frames (its source has {src})",
                hint="give exactly one mask per frame (in the same order as the frames)",
            )
        pick = self._pick(len(masks), t)
        out = working(self._like, t, (h, w), bool)
        for k, i in enumerate(pick):
            out[k] = masks[i]
        if progress:
            progress(t, t)
        return out


PROMPT_INPUTS = ("box", "boxes", "point_coords", "points", "point_labels", "labels")


class OnnxSegmenter:
    """A segmentation network from a local ``.onnx`` file (nothing is downloaded): salient-object
    and matting models, or promptable ones (SAM-style) that take a box and/or points.

    Inputs, matched by name: the image is the model's first 4-d input (or one named ``image``):
    RGB resized to the model's input size (its static input shape, else ``input_size`` square),
    scaled to [0, 1], minus ``mean``, over ``std``, NCHW float32, batch 1 (the U^2-Net / ISNet /
    MODNet convention). Optional prompts, fed when the model has an input of that name:
    ``box`` / ``boxes``: (1, 4) float32 x0, y0, x1, y1 in the model's input pixels;
    ``point_coords`` / ``points``: (1, N, 2) float32 x, y in input pixels, with
    ``point_labels`` / ``labels``: (1, N) float32, 1 = animal, 0 = background (here one positive
    point, the box's centre). The prompt box is the user's ``--box`` on frame ``box_frame``; each
    later (and earlier) frame is prompted with the box of its neighbour's mask grown by
    ``prompt_margin``, so the prompt follows the animal; with no box the whole frame is the box.
    Any other input is an error that lists what is fed.

    Output: the first output's first map ((1, 1, h, w), (1, h, w) or (1, h, w, 1)): probabilities,
    or mask logits (values outside [0, 1] go through a sigmoid), min-max normalised when
    ``normalize`` (what U^2-Net's reference code does; off for promptable models), resized to the
    frame, thresholded at ``threshold``. With a box and an unpromptable model, only the components
    that touch it are kept on every frame.
    """

    name = "onnx"

    def __init__(
        self,
        model: str | Path | None = None,
        input_size: int = 320,
        mean: Sequence[float] = (0.485, 0.456, 0.406),
        std: Sequence[float] = (0.229, 0.224, 0.225),
        threshold: float = 0.5,
        normalize: bool = True,
        threads: int = 0,
        prompt_margin: float = 0.1,
    ) -> None:
        if model is None:
            raise UsageError(
                "the onnx segmenter needs a model", hint="pass --model PATH to a local .onnx file"
            )
        path = Path(model).expanduser()
        if not path.is_file():
            raise InputError(f"ONNX model {path} does not exist", hint="give the path of a local .onnx file")
        try:
            import onnxruntime as ort
        except ImportError:
            raise MissingDependencyError(
                "the onnx segmenter needs the onnxruntime package", hint="pip install onnxruntime"
            ) from None
        opts = ort.SessionOptions()
        if threads:
            opts.intra_op_num_threads = threads
        try:
            self.session = ort.InferenceSession(
                str(path), sess_options=opts, providers=["CPUExecutionProvider"]
            )
        except Exception as exc:
            raise InputError(
                f"{path.name} is not a loadable ONNX model: {str(exc).splitlines()[0][:200]}"
            ) from None
        inputs = self.session.get_inputs()
        images = [i for i in inputs if i.name == "image"] or [i for i in inputs if len(i.shape) == 4]
        inp = images[0] if images else inputs[0]
        self.input_name = inp.name
        self.prompts = {i.name for i in inputs if i.name != inp.name}
        unknown = self.prompts - set(PROMPT_INPUTS)
        if unknown:
            raise InputError(
                f"{path.name} has inputs {', '.join(sorted(unknown))} the onnx segmenter cannot feed",
                hint=f"it feeds an NCHW image and optionally {', '.join(PROMPT_INPUTS)}",
            )
        self.prompt_margin = prompt_margin
        shape = list(inp.shape)
        if len(shape) != 4:
            raise InputError(
                f"{path.name} takes a {len(shape)}-d input, the onnx segmenter feeds NCHW images"
            )
        hh, ww = shape[2], shape[3]
        self.size = (ww if isinstance(ww, int) else input_size, hh if isinstance(hh, int) else input_size)
        self.mean = np.asarray(mean, np.float32).reshape(1, 3, 1, 1)
        self.std = np.asarray(std, np.float32).reshape(1, 3, 1, 1)
        self.threshold = threshold
        self.normalize = normalize

    def probability(self, frame: np.ndarray, box=None) -> np.ndarray:
        """(H, W, 3) uint8 RGB, optional prompt box (x, y, w, h frame pixels) -> (H, W) float32
        foreground probability."""
        h, w = frame.shape[:2]
        x = cv2.resize(
            frame, self.size, interpolation=cv2.INTER_AREA if self.size[0] < w else cv2.INTER_LINEAR
        )
        x = x.astype(np.float32).transpose(2, 0, 1)[None] / 255.0
        x = (x - self.mean) / self.std
        feed = {self.input_name: x}
        if self.prompts:
            feed.update(self._prompt_feed(box if box is not None else (0, 0, w, h), w, h))
        out = np.asarray(self.session.run(None, feed)[0], np.float32)
        m = out.reshape(-1, *out.shape[-2:])[0] if out.ndim != 4 or out.shape[-1] != 1 else out[0, ..., 0]
        if m.min() < 0 or m.max() > 1:
            m = 1.0 / (1.0 + np.exp(-m))
        if self.normalize and m.max() > m.min():
            m = (m - m.min()) / (m.max() - m.min())
        return cv2.resize(m, (w, h), interpolation=cv2.INTER_LINEAR)

    def _prompt_feed(self, box, w: int, h: int) -> dict[str, np.ndarray]:
        """Prompt inputs for a box (x, y, w, h) in frame pixels, in the model's input pixels."""
        sx, sy = self.size[0] / w, self.size[1] / h
        x, y, bw, bh = (float(v) for v in box)
        corners = np.array([[x * sx, y * sy, (x + bw) * sx, (y + bh) * sy]], np.float32)
        centre = np.array([[[(x + bw / 2) * sx, (y + bh / 2) * sy]]], np.float32)
        values = {
            "box": corners,
            "boxes": corners,
            "point_coords": centre,
            "points": centre,
            "point_labels": np.ones((1, 1), np.float32),
            "labels": np.ones((1, 1), np.float32),
        }
        return {k: values[k] for k in self.prompts}

    def segment(
        self, frames: np.ndarray, box=None, progress: Progress | None = None, box_frame: int = 0
    ) -> np.ndarray:
        from .cues import box_mask, box_of, largest_components

        t, h, w = frames.shape[:3]
        out = working(frames, t, (h, w), bool)
        if not self.prompts:
            keep = box_mask((h, w), tuple(int(v) for v in box)) if box is not None else None
            for i in range(t):
                out[i] = self.probability(frames[i]) > self.threshold
                if keep is not None:
                    out[i] = largest_components(out[i], keep_ratio=1e-9, reference=keep) & out[i]
                if progress:
                    progress(i + 1, t)
            return out
        if not 0 <= box_frame < t:
            raise UsageError(f"--box-frame {box_frame} is not a frame of this {t}-frame video")
        # prompted: from the box's frame outwards, each frame prompted by its neighbour's mask
        order = [box_frame, *range(box_frame + 1, t), *range(box_frame - 1, -1, -1)]
        for n, i in enumerate(order):
            prompt = box
            if i != box_frame:
                prev = box_of(out[i - 1] if i > box_frame else out[i + 1])
                if prev is not None:
                    m = self.prompt_margin * max(prev[2], prev[3])
                    prompt = (prev[0] - m, prev[1] - m, prev[2] + 2 * m, prev[3] + 2 * m)
            out[i] = self.probability(frames[i], prompt) > self.threshold
            if progress:
                progress(n + 1, t)
        return out
