"""Built-in glTF 2.0 importer (``.glb``, ``.gltf``)."""

from __future__ import annotations

from pathlib import Path

from ..components import ImporterSpec
from ..plugins import hookimpl


def _load(path: Path, name: str):
    from ..io.gltf_import import load_gltf  # numpy-heavy: imported only when used

    return load_gltf(path, name)


@hookimpl
def register_importers(register):
    register(
        ImporterSpec("gltf", (".glb", ".gltf"), _load, "glTF 2.0 skinned meshes with skins and animations")
    )
