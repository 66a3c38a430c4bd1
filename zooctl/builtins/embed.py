"""Built-in image embedders for retrieval: ``effnet`` (appearance), ``silhouette`` (mask shape) and
``procnet`` (trained on procedural animals)."""

from __future__ import annotations

from typing import Any

from ..components import ComponentSpec
from ..plugins import hookimpl


def _effnet(device: str = "cpu", **options: Any) -> Any:
    from ..embed.effnet_embedder import EffnetEmbedder

    return EffnetEmbedder(device=device, **options)


def _silhouette(device: str = "cpu", **options: Any) -> Any:
    from ..embed.silhouette import SilhouetteEmbedder

    return SilhouetteEmbedder(device=device, **options)


def _procnet(device: str = "cpu", **options: Any) -> Any:
    from ..embed.procnet import ProcnetEmbedder

    return ProcnetEmbedder(device=device, **options)


@hookimpl
def register_embedders(register):
    register(
        ComponentSpec(
            "embedder", "effnet", _effnet, "EfficientNet-Lite0 ImageNet features (1280-d) of RGB crops"
        )
    )
    register(
        ComponentSpec("embedder", "silhouette", _silhouette, "shape descriptor of the animal's mask (576-d)")
    )
    register(
        ComponentSpec(
            "embedder",
            "procnet",
            _procnet,
            "head trained on procedural animals over effnet + silhouette features (128-d; `zooctl embed train`)",
        )
    )
