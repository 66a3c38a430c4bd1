"""Built-in BVH exporter (``bvh``): skeleton and motion for motion-capture tools.

Registered by the ``gltf_export`` entry point's hook (`zooctl.builtins.gltf_export`), so an
existing editable install finds it without re-reading zooctl's entry points.
"""

from __future__ import annotations

from pathlib import Path

from ..components import ExporterSpec


def _save(asset, path: Path, clips=None, **options):
    from ..io.bvh import save_bvh

    return save_bvh(asset, path, clips)


def register_bvh(register) -> None:
    register(
        ExporterSpec(
            "bvh", ("bvh",), _save, "BVH: skeleton offsets and per-frame joint rotations (no mesh)", (".bvh",)
        )
    )
