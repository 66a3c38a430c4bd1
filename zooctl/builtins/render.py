"""Built-in differentiable renderers: ``soft`` (SoftRas silhouettes), ``fast`` (splatting), ``flow``."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ..components import ComponentSpec
from ..plugins import hookimpl

if TYPE_CHECKING:  # torch loads when a renderer is built, not when the plugin registers
    from ..render.base import FlowRenderer, SilhouetteRenderer


def _soft(
    image_size: int | tuple[int, int] | None, device: str = "cpu", **options: Any
) -> SilhouetteRenderer:
    from ..render.soft import SoftSilhouette

    return SoftSilhouette(image_size, device=device, **options)


def _fast(
    image_size: int | tuple[int, int] | None, device: str = "cpu", **options: Any
) -> SilhouetteRenderer:
    from ..render.splat import SplatSilhouette

    return SplatSilhouette(image_size, device=device, **options)


def _flow(
    image_size: int | tuple[int, int] | None = None, device: str = "cpu", **options: Any
) -> FlowRenderer:
    from ..render.raster import RasterFlow

    return RasterFlow(image_size, device=device, **options)


@hookimpl
def register_renderers(register):
    register(
        ComponentSpec("renderer", "soft", _soft, "SoftRas-style soft silhouette (B, H, W), per-face windows")
    )
    register(
        ComponentSpec("renderer", "fast", _fast, "cheap splatted silhouette (B, H, W) for large batches")
    )
    register(
        ComponentSpec("renderer", "flow", _flow, "hard z-buffer: optical flow, depth, face ids, barycentrics")
    )
