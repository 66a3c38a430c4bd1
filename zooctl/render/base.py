"""The renderer interfaces, and the one way the rest of zooctl builds a renderer: by its name in
the plugin registry (`zooctl.hookspecs.register_renderers`).

A renderer's factory is called as ``factory(image_size, device="cpu", **options)``; the object
it returns is a ``torch.nn.Module``-like callable of one of two kinds:

- `SilhouetteRenderer` (built in: ``soft``, ``fast``): ``(vertices (B, V, 3), faces (F, 3) long,
  camera)`` -> coverage (B, H, W) in [0, 1], differentiable with respect to ``vertices``. ``H, W``
  are ``camera.height, camera.width`` (a `zooctl.render.camera.Camera` batch of B). The fit's
  ``stage1.renderer`` / ``stage2.renderer`` (``zooctl fit --renderer``) name one of these.
- `FlowRenderer` (built in: ``flow``): ``(vertices, faces, camera, vertices_next)`` -> a dict with
  ``flow`` (B, H, W, 2) pixels and ``mask`` (B, H, W) bool, at least; the fit's flow term uses it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import torch

from ..errors import UsageError

if TYPE_CHECKING:
    from .camera import Camera

Tensor = torch.Tensor


@runtime_checkable
class SilhouetteRenderer(Protocol):
    def __call__(self, vertices: Tensor, faces: Tensor, camera: Camera) -> Tensor: ...


@runtime_checkable
class FlowRenderer(Protocol):
    def __call__(
        self, vertices: Tensor, faces: Tensor, camera: Camera, vertices_next: Tensor
    ) -> dict[str, Tensor]: ...


def renders_flow(renderer: SilhouetteRenderer | FlowRenderer) -> bool:
    """True for a `FlowRenderer` (its call takes ``vertices_next``), False for a silhouette one."""
    import inspect

    try:
        call = getattr(renderer, "forward", renderer)  # an nn.Module's __call__ hides its signature
        return "vertices_next" in inspect.signature(call).parameters
    except (TypeError, ValueError):
        return False


def get_renderer(
    name: str, image_size: int | tuple[int, int] | None = None, device: str = "cpu", **options: Any
) -> SilhouetteRenderer | FlowRenderer:
    """Build the renderer registered as ``name``; an unknown name is a `NotFoundError` listing them."""
    from ..plugins import get_registry

    return get_registry().get("renderer", name).create(image_size=image_size, device=device, **options)


def check_silhouette(name: str, out: object, batch: int, height: int, width: int) -> Tensor:
    """``out`` if it is the (B, H, W) coverage a silhouette renderer returns, else a clear error
    (e.g. ``--renderer flow``, which renders flow, not silhouettes)."""
    if not isinstance(out, torch.Tensor) or tuple(out.shape) != (batch, height, width):
        got = type(out).__name__ if not isinstance(out, torch.Tensor) else f"shape {tuple(out.shape)}"
        raise UsageError(
            f"renderer {name!r} does not render silhouettes: expected a ({batch}, {height}, {width}) "
            f"tensor, got {got}",
            hint="pick a silhouette renderer, e.g. --renderer soft or fast (see `zooctl plugins`)",
        )
    return out
