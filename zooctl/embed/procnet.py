"""The ``procnet`` embedder: a head trained on procedural animals over frozen features.

Input: the RGB crop and its mask (``input_kind = "rgb+mask"``). Features: EfficientNet-Lite0's
pooled 1280-d features of the crop and the 576-d silhouette descriptor of the mask (the same
extractors as the ``effnet`` and ``silhouette`` embedders), concatenated in the order the weights
file names; then ``relu(x W1 + b1) W2 + b2``, unit length. Pure numpy at inference (a search stays
torch-free). Weights: ``weights=``, else ``ZOOCTL_PROCNET_WEIGHTS``, else `default_weights`
(``models/procnet.npz`` in the store, where `zooctl embed train` writes them;
`zooctl.retrieval.train_embedder`). None ship in the package: the head has not beaten the default
embedders on the leave-one-out benchmark (BENCHMARKS.md). The identity carries the file's digest,
so banks embedded by other weights are told to reindex.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from ..errors import InputError
from .base import check_images, check_masks, file_digest, l2_normalize


def default_weights() -> Path:
    """Where `zooctl embed train` writes the weights by default: STORE/models/procnet.npz."""
    from ..paths import default_store

    return default_store() / "models" / "procnet.npz"


def weights_file(weights: str | Path | None = None) -> Path:
    """The weights to load: the argument, ZOOCTL_PROCNET_WEIGHTS, else `default_weights`."""
    p = Path(weights or os.environ.get("ZOOCTL_PROCNET_WEIGHTS") or default_weights()).expanduser()
    if not p.is_file():
        raise InputError(
            f"procnet weights {p} do not exist",
            hint="train them with `zooctl embed train` (about 6 min on 2 CPU cores) "
            "or point ZOOCTL_PROCNET_WEIGHTS at a weights .npz",
        )
    return p


def load_head(path: Path) -> tuple[dict[str, np.ndarray], dict]:
    """The head's float32 matrices and its info (inputs, labels, config)."""
    try:
        with np.load(path) as z:
            w = {k: z[k].astype(np.float32) for k in ("w1", "b1", "w2", "b2")}
            info = json.loads(str(z["info"]))
    except (OSError, KeyError, ValueError) as exc:
        raise InputError(f"{path} is not a procnet weights file ({exc})") from None
    return w, info


def apply_head(w: dict[str, np.ndarray], x: np.ndarray) -> np.ndarray:
    """(N, Din) features -> (N, dim) unit embeddings."""
    h = np.maximum(x @ w["w1"] + w["b1"], 0.0)
    return l2_normalize(h @ w["w2"] + w["b2"])


class ProcnetEmbedder:
    """See the module docstring."""

    name = "procnet"
    input_kind = "rgb+mask"

    def __init__(self, device: str = "cpu", weights: str | Path | None = None):
        from .effnet_embedder import EffnetEmbedder
        from .silhouette import SilhouetteEmbedder

        path = weights_file(weights)
        self.w, self.info = load_head(path)
        self.inputs = list(self.info.get("inputs", ["effnet", "silhouette"]))
        self.dim = int(self.w["w2"].shape[1])
        self.identity = f"procnet/{file_digest(path)}"
        self._features = {}
        if "effnet" in self.inputs:
            self._features["effnet"] = EffnetEmbedder(device=device)
        if "silhouette" in self.inputs:
            self._features["silhouette"] = SilhouetteEmbedder()

    def features(self, images: np.ndarray, masks: np.ndarray) -> np.ndarray:
        """(N, S, S, 3) uint8 and (N, S, S) bool -> (N, Din) frozen features, in the weights' order."""
        parts = []
        for f in self.inputs:
            e = self._features[f]
            parts.append(
                e.embed_batch(check_masks(masks) if e.input_kind == "mask" else check_images(images))
            )
        return np.concatenate(parts, 1)

    def embed_batch(self, images: np.ndarray, masks: np.ndarray) -> np.ndarray:
        """(N, S, S, 3) uint8 crops and their (N, S, S) masks -> (N, dim) unit embeddings."""
        return apply_head(self.w, self.features(images, masks))
