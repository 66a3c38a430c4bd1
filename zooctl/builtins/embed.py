"""Built-in image embedders for retrieval: ``effnet`` (appearance), ``silhouette`` (mask shape) and
``procnet`` (trained on procedural animals)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ..components import ComponentSpec
from ..plugins import hookimpl

if TYPE_CHECKING:  # an embedder's weights load when it is built, not when the plugin registers
    from ..embed.base import Embedder


def _effnet(device: str = "cpu", **options: Any) -> Embedder:
    from ..embed.effnet_embedder import EffnetEmbedder

    return EffnetEmbedder(device=device, **options)


def _silhouette(device: str = "cpu", **options: Any) -> Embedder:
    from ..embed.silhouette import SilhouetteEmbedder

    return SilhouetteEmbedder(device=device, **options)


def _procnet(device: str = "cpu", **options: Any) -> Embedder:
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
