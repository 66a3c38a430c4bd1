"""Query frames for retrieval: decode a video (file, image folder, DAVIS folder), pick K frames,
crop each to the animal through its mask (`zooctl.retrieval.crop`), as bank views are cropped.

Masks come from, in order: ``--masks DIR`` (one image per source frame, natural order, non-zero
= animal), a DAVIS ``Annotations/`` folder beside ``JPEGImages/``. Without masks the frames are
centre-cropped to a square and mask-only embedders (``silhouette``) cannot be used.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError, NotFoundError, UsageError
from ..geometry import nonempty_frames
from .crop import square_crop

DEFAULT_QUERY_FRAMES = 8


@dataclass
class QueryFrames:
    """K query crops. images (K, S, S, 3) uint8; masks (K, S, S) bool or None; frames (K,) indices
    of the chosen frames in the decoded video; source: what was decoded; identities: {embedder:
    `zooctl.embed.base.embedder_identity`} of the embedders that embedded it (set by the search);
    classes: (K, 1000) ImageNet probabilities of the crops (set by the search when it embeds with
    effnet; `zooctl.retrieval.semantic`), or None; class_images: (K, S, S, 3) the crops the
    classifier sees instead of ``images`` (`classifier_crops`), or None: ``images``."""

    images: np.ndarray
    masks: np.ndarray | None
    frames: np.ndarray
    source: str
    notes: list[str] = field(default_factory=list)
    identities: dict[str, str] = field(default_factory=dict)
    classes: np.ndarray | None = None
    class_images: np.ndarray | None = None


def sample_indices(n: int, k: int) -> np.ndarray:
    """k indices spread evenly over range(n) (all of them when n <= k)."""
    if n <= k:
        return np.arange(n)
    return np.unique(np.round(np.linspace(0, n - 1, k)).astype(int))


def read_mask(path: Path, shape: tuple[int, int]) -> np.ndarray:
    """A mask image -> (H, W) bool at ``shape`` (non-zero pixels are the animal)."""
    import cv2

    m = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if m is None:
        raise InputError(f"{path} is not a readable mask image")
    if m.ndim == 3:
        m = m.max(axis=2)
    if m.shape != shape:
        m = cv2.resize(m, (shape[1], shape[0]), interpolation=cv2.INTER_NEAREST)
    return m > 0


def crops_from_frames(
    frames: np.ndarray, masks: np.ndarray | None, k: int, size: int
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Pick up to k frames (with a non-empty mask when masks are given) and crop them.

    frames (T, H, W, 3) uint8, masks (T, H, W) bool or None -> crops (K, S, S, 3), masks (K, S, S)
    or None, chosen frame indices (K,).
    """
    import cv2

    T = len(frames)
    if masks is not None:
        usable = nonempty_frames(masks)
        if len(usable) == 0:
            raise InputError(
                "every mask of the query video is empty", hint="check the masks, or search without them"
            )
        chosen = usable[sample_indices(len(usable), k)]
        crops = [square_crop(frames[i], masks[i], size) for i in chosen]
        return np.stack([c[0] for c in crops]), np.stack([c[1] for c in crops]), chosen
    chosen = sample_indices(T, k)
    out = []
    for i in chosen:
        h, w = frames[i].shape[:2]
        s = min(h, w)
        y0, x0 = (h - s) // 2, (w - s) // 2
        out.append(
            cv2.resize(frames[i][y0 : y0 + s, x0 : x0 + s], (size, size), interpolation=cv2.INTER_AREA)
        )
    return np.stack(out), None, chosen


def classifier_crops(
    frames: np.ndarray, masks: np.ndarray | None, chosen: np.ndarray, size: int
) -> np.ndarray | None:
    """The crops of ``chosen`` frames for the semantic term's classifier: `crops_from_frames`'
    squares kept within the frame (`square_crop`'s ``inside``); None without masks (the centre
    crops lie within the frame already)."""
    if masks is None:
        return None
    return np.stack([square_crop(frames[i], masks[i], size, inside=True)[0] for i in chosen])


def stored_query(videos, name: str, k: int, size: int) -> QueryFrames:
    """K crops of a stored video, decoding only the K sampled frames (frames with a mask first).
    ``frames`` are indices into the stored video."""

    def pick(boxes: np.ndarray) -> np.ndarray:  # boxes (T, 4); width 0: empty mask
        usable = np.flatnonzero(boxes[:, 2] > 0)
        return usable[sample_indices(len(usable), k)] if len(usable) else sample_indices(len(boxes), k)

    idx, frames, masks = videos.read_some(name, pick)
    has_masks = len(idx) > 0 and bool(masks.reshape(len(masks), -1).any(1).all())
    images, crop_masks, chosen = crops_from_frames(frames, masks if has_masks else None, k, size)
    notes = [] if has_masks else ["the stored video has no masks: frames are centre-cropped"]
    query = QueryFrames(images, crop_masks, idx[chosen], f"stored video {name}", notes)
    query.class_images = classifier_crops(frames, masks if has_masks else None, chosen, size)
    return query


def load_query(
    source: str | Path,
    k: int = DEFAULT_QUERY_FRAMES,
    size: int = 224,
    masks_dir: str | Path | None = None,
    store_root: str | Path | None = None,
) -> QueryFrames:
    """Decode ``source`` and return K cropped query frames. See the module docstring.

    ``source`` is a video file, a frame folder, a DAVIS folder, or (with ``store_root``) the name
    of a video in the store, whose stored masks are used for cropping.
    """
    from ..video.decode import decode, image_files

    if k < 1:
        raise UsageError(f"--frames {k} must be at least 1")
    path = Path(source).expanduser()
    if not path.exists() and store_root is not None and masks_dir is None:
        from ..store.videos import VideoStore

        videos = VideoStore(store_root)
        if videos.exists(str(source)):
            return stored_query(videos, str(source), k, size)
    if not path.exists():
        raise NotFoundError(
            f"{source} is not a file or folder",
            hint="give a video file, a folder of frames, a DAVIS folder (JPEGImages/, Annotations/) "
            "or the name of a stored video (`zooctl video list`)",
        )
    video = decode(path)
    frames = video.frames
    T, H, W = frames.shape[:3]
    masks = None
    notes = []
    if masks_dir is not None:
        mdir = Path(masks_dir).expanduser()
        if not mdir.is_dir():
            raise InputError(
                f"--masks {mdir} is not a folder", hint="give a folder with one mask image per frame"
            )
        files = image_files(mdir)
        need = int(video.source_indices.max()) + 1
        if len(files) < need:
            raise InputError(
                f"--masks {mdir} has {len(files)} images, the video needs {need}",
                hint="one mask per source frame, in frame order",
            )
        masks = np.stack([read_mask(files[int(i)], (H, W)) for i in video.source_indices])
    elif video.annotations is not None:
        masks = np.zeros((T, H, W), bool)
        found = np.zeros(T, bool)
        for t, img in enumerate(video.image_files):
            p = video.annotations / f"{img.stem}.png"
            if p.exists():
                masks[t], found[t] = read_mask(p, (H, W)), True
        if not found.any():
            masks = None
            notes.append(f"no annotation in {video.annotations} matches a frame: frames are centre-cropped")
        else:
            frames, masks = frames[found], masks[found]
    if masks is None and not notes:
        notes.append("no masks: frames are centre-cropped and mask-only embedders are skipped")
    images, crop_masks, chosen = crops_from_frames(frames, masks, k, size)
    query = QueryFrames(images, crop_masks, chosen, str(path), notes)
    query.class_images = classifier_crops(frames, masks, chosen, size)
    return query
