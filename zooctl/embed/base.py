"""The embedder interface and the helpers every embedder shares.

An embedder (registered under the ``embedder`` kind, see `zooctl.hookspecs.register_embedders`)
is an object with

- ``name: str`` and ``dim: int``;
- ``input_kind``: ``"rgb"`` (the default of the hook spec) or ``"mask"``;
- ``embed_batch(x) -> (N, dim) float32``, unit-norm rows, compared by cosine distance. ``x`` is
  (N, H, W, 3) uint8 RGB for ``"rgb"`` embedders and (N, H, W) bool masks for ``"mask"`` ones;
- optionally ``identity: str``, which changes whenever the embeddings would (other weights, input
  size, options), e.g. a digest of the weights file (`file_digest`). Bank views and cached query
  embeddings record it, so a search never compares embeddings of two versions of one embedder
  (`embedder_identity`; without the attribute, the name and ``dim`` stand for it).

Retrieval hands every embedder square crops centred on the animal (`zooctl.retrieval.crop`), the
same way for rendered bank views and for query video frames.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from ..errors import InputError

DEFAULT_EMBEDDERS = ("effnet", "silhouette")


class Embedder(Protocol):
    name: str
    dim: int
    input_kind: str

    def embed_batch(self, x: np.ndarray) -> np.ndarray: ...


_DIGESTS: dict[tuple[str, int, int], str] = {}


def file_digest(path: str | Path) -> str:
    """The first 16 hex digits of the SHA-256 of a file (weights), computed once per process and
    file version (path, size, mtime)."""
    p = Path(path).expanduser().resolve()
    st = p.stat()
    key = (str(p), int(st.st_size), int(st.st_mtime_ns))
    if key not in _DIGESTS:
        h = hashlib.sha256()
        with open(p, "rb") as f:
            for block in iter(lambda: f.read(1 << 22), b""):
                h.update(block)
        _DIGESTS[key] = h.hexdigest()[:16]
    return _DIGESTS[key]


def embedder_identity(embedder: Embedder) -> str:
    """What distinguishes this embedder's embeddings from another version's (module docstring)."""
    ident = getattr(embedder, "identity", None)
    return str(ident) if ident else f"{embedder.name}/{int(embedder.dim)}"


def l2_normalize(x: np.ndarray, eps: float = 1e-12) -> np.ndarray:
    """Rows of (N, D) scaled to unit length (zero rows stay zero), as float32."""
    x = np.asarray(x, dtype=np.float32)
    return x / np.maximum(np.linalg.norm(x, axis=-1, keepdims=True), eps)


def check_images(images: Any) -> np.ndarray:
    """(N, H, W, 3) uint8, or a clear `InputError`."""
    arr = np.asarray(images)
    if arr.ndim == 3 and arr.shape[-1] == 3:
        arr = arr[None]
    if arr.ndim != 4 or arr.shape[-1] != 3 or arr.shape[0] == 0:
        raise InputError(f"an embedder needs (N, H, W, 3) RGB images, got shape {arr.shape}")
    if arr.dtype != np.uint8:
        raise InputError(
            f"an embedder needs uint8 images, got {arr.dtype}",
            hint="convert with (img * 255).astype(np.uint8)",
        )
    return arr


def check_masks(masks: Any) -> np.ndarray:
    """(N, H, W) bool, or a clear `InputError`."""
    arr = np.asarray(masks)
    if arr.ndim == 2:
        arr = arr[None]
    if arr.ndim != 3 or arr.shape[0] == 0:
        raise InputError(f"a mask embedder needs (N, H, W) masks, got shape {arr.shape}")
    return arr.astype(bool)


def torch_threads() -> int:
    """Threads for CPU inference: ZOOCTL_TORCH_THREADS, else torch's default (bench/embed.py measures both)."""
    v = os.environ.get("ZOOCTL_TORCH_THREADS")
    if v:
        try:
            return max(1, int(v))
        except ValueError:
            raise InputError(
                f"ZOOCTL_TORCH_THREADS={v!r} is not a number", hint="e.g. ZOOCTL_TORCH_THREADS=1"
            ) from None
    return 0


def resize_batch(images: np.ndarray, size: int) -> np.ndarray:
    """(N, H, W, 3) uint8 -> (N, size, size, 3) uint8 with area/bilinear resampling (OpenCV)."""
    import cv2

    if images.shape[1] == size and images.shape[2] == size:
        return images
    interp = cv2.INTER_AREA if images.shape[1] > size else cv2.INTER_LINEAR
    return np.stack([cv2.resize(im, (size, size), interpolation=interp) for im in images])


def get_embedder(name: str, device: str = "cpu", **options: Any) -> Embedder:
    """Build the embedder registered as ``name`` (built-in or from a plugin)."""
    from ..plugins import get_registry

    return get_registry().get("embedder", name).create(device=device, **options)
