"""The ``effnet`` embedder: 1280-d pooled EfficientNet-Lite0 features of RGB crops, unit length.

Two backends compute the same features (to about 1e-5): the torch model (`zooctl.embed.effnet`,
for CUDA and for batches when torch is loaded anyway, e.g. while `bank add` renders views) and the
numpy one (`zooctl.embed.effnet_numpy`), which spares a search the torch import (its cost:
BENCHMARKS.md, Retrieval). ``backend="auto"`` takes numpy on the CPU when torch has not been
imported yet.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from .effnet_arch import HEAD_CHANNELS, INPUT_MEAN, INPUT_SIZE, INPUT_STD, weights_path

BACKENDS = ("auto", "torch", "numpy")
NUMPY_CHUNK = 1  # images per numpy forward pass: one at a time keeps a layer's activations in the CPU
# cache (faster than a batch on one core) and bounds the peak memory


def choose_backend(backend: str, device: str) -> str:
    """ "torch" or "numpy" for a requested backend and device (see the module docstring)."""
    from ..errors import UsageError

    if backend not in BACKENDS:
        raise UsageError(f"unknown effnet backend {backend!r}", hint=f"choose one of {', '.join(BACKENDS)}")
    if backend == "numpy" and device != "cpu":
        raise UsageError(
            f"the numpy effnet backend runs on the CPU only, not {device!r}", hint="use --device cpu"
        )
    if backend == "auto":
        return "numpy" if device == "cpu" and "torch" not in sys.modules else "torch"
    return backend


def normalise(images: np.ndarray, size: int = INPUT_SIZE) -> np.ndarray:
    """(N, H, W, 3) uint8 RGB -> (N, size, size, 3) float32 network input (NHWC)."""
    from .base import resize_batch

    return (resize_batch(images, size).astype(np.float32) - INPUT_MEAN) / INPUT_STD


class EffnetEmbedder:
    """See the module docstring. ``size``: the square input resolution (224 as trained; smaller is
    faster); ``batch``: images per torch forward pass (bounds memory); ``weights``: another state
    dict of the same network; ``backend``: auto, torch or numpy."""

    name = "effnet"
    dim = HEAD_CHANNELS
    input_kind = "rgb"

    def __init__(
        self,
        device: str = "cpu",
        size: int = INPUT_SIZE,
        batch: int = 32,
        weights: str | Path | None = None,
        backend: str = "auto",
    ):
        self.backend = choose_backend(backend, device)
        self.size = int(size)
        self.batch = int(batch)
        path = weights_path() if weights is None else Path(weights)
        from .base import file_digest

        # Both backends compute the same features, so the identity names the weights, not the
        # backend. The shipped file's name carries its content hash (torch hub style), which spares
        # a search hashing 19 MB; other weights are hashed.
        tag = path.stem if weights is None else file_digest(path)
        self.identity = f"effnet-lite0/{tag}/{self.size}px"
        if self.backend == "numpy":
            from .effnet_numpy import load_numpy_model

            self.device = "cpu"
            self.model = load_numpy_model(path)
            return
        import torch

        from .base import torch_threads
        from .effnet import fold_batchnorm, load_pretrained

        threads = torch_threads()
        if threads:
            torch.set_num_threads(threads)
        self.device = torch.device(device)
        self.model = fold_batchnorm(load_pretrained(path)).to(self.device)
        if self.device.type == "cpu":
            self.model = self.model.to(memory_format=torch.channels_last)

    def _chunks(self, images: np.ndarray):
        step = min(self.batch, NUMPY_CHUNK) if self.backend == "numpy" else self.batch
        for i in range(0, len(images), step):
            yield images[i : i + step]

    def _forward(self, images: np.ndarray, logits: bool) -> np.ndarray:
        x = normalise(images, self.size)
        if self.backend == "numpy":
            return self.model.logits(x) if logits else self.model.features(x)
        import torch

        with torch.inference_mode():
            t = torch.from_numpy(x).permute(0, 3, 1, 2).to(self.device)
            if self.device.type == "cpu":
                t = t.contiguous(memory_format=torch.channels_last)
            out = self.model(t) if logits else self.model.features(t)
            return out.float().cpu().numpy()

    def embed_batch(self, images: np.ndarray) -> np.ndarray:
        """(N, H, W, 3) uint8 -> (N, 1280) float32 unit-norm embeddings."""
        from .base import check_images, l2_normalize

        images = check_images(images)
        return l2_normalize(np.concatenate([self._forward(c, False) for c in self._chunks(images)]))

    def embed_and_classify(self, images: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One forward pass: (N, 1280) unit-norm embeddings and (N, 1000) ImageNet probabilities."""
        from .base import check_images, l2_normalize

        images = check_images(images)
        feats = np.concatenate([self._forward(c, False) for c in self._chunks(images)]).astype(np.float32)
        if self.backend == "numpy":
            w, b = self.model.fc_weight, self.model.fc_bias
        else:
            w = self.model._fc.weight.detach().float().cpu().numpy().T
            b = self.model._fc.bias.detach().float().cpu().numpy()
        return l2_normalize(feats), _softmax(feats @ w + b)

    def classify(self, images: np.ndarray) -> np.ndarray:
        """(N, H, W, 3) uint8 -> (N, 1000) ImageNet class probabilities."""
        from .base import check_images

        images = check_images(images)
        return _softmax(np.concatenate([self._forward(c, True) for c in self._chunks(images)]))


def _softmax(z: np.ndarray) -> np.ndarray:
    z = np.exp(z.astype(np.float64) - z.max(-1, keepdims=True))
    return (z / z.sum(-1, keepdims=True)).astype(np.float32)
