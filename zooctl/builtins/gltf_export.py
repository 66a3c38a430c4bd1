"""Built-in exporters: glTF binary (``glb``) and BVH (``bvh``, `zooctl.builtins.bvh`)."""

from __future__ import annotations

from pathlib import Path

from ..components import ExporterSpec
from ..plugins import hookimpl
from .bvh import register_bvh


def _save(asset, path: Path, clips=None, **options):
    from ..io.gltf_export import save_glb

    return save_glb(asset, path, clips)


@hookimpl
def register_exporters(register):
    register(
        ExporterSpec(
            "glb", ("glb",), _save, "glTF 2.0 binary: mesh, skin, inverse bind matrices, animations, texture"
        )
    )
    register_bvh(register)
