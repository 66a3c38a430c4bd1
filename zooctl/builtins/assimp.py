"""Built-in FBX / COLLADA / BVH importer through the ``assimp`` command (package assimp-utils)."""

from __future__ import annotations

from pathlib import Path

from ..components import ImporterSpec
from ..plugins import hookimpl


def _load(path: Path, name: str):
    from ..io.assimp import load_with_assimp

    return load_with_assimp(path, name)


@hookimpl
def register_importers(register):
    register(
        ImporterSpec(
            "assimp",
            (".fbx", ".dae", ".bvh"),
            _load,
            "FBX, COLLADA and BVH via the assimp command (converted to glTF)",
        )
    )
