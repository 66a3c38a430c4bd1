"""Built-in USD exporter (``usd``, ``usda``, ``usdc``, ``usdz``) and UsdSkel importer."""

from __future__ import annotations

from pathlib import Path

from ..components import ExporterSpec, ImporterSpec
from ..plugins import hookimpl


def _save(asset, path: Path, clips=None, **options):
    from ..io.usd_export import save_usd  # pxr is heavy: imported only when used

    return save_usd(asset, path, clips, **options)


def _preload():
    from pxr import Sdf, Usd, UsdGeom, UsdSkel, Vt  # noqa: F401

    from ..io import usd_export  # noqa: F401


def _load(path: Path, name: str):
    from ..io.usd_import import load_usd

    return load_usd(path, name)


@hookimpl
def register_exporters(register):
    register(
        ExporterSpec(
            "usd",
            ("usd", "usda", "usdc", "usdz"),
            _save,
            "UsdSkel: SkelRoot, Skeleton, skinned Mesh, one SkelAnimation per clip",
            preload=_preload,
        )
    )


@hookimpl
def register_importers(register):
    register(
        ImporterSpec(
            "usd",
            (".usd", ".usda", ".usdc", ".usdz"),
            _load,
            "UsdSkel skinned meshes with their SkelAnimations",
        )
    )
