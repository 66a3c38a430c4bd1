"""What plugins register: small frozen specs, one per kind of component.

A plugin's register-callback hook (see `zooctl.hookspecs`) calls ``register(spec)`` once per
component it provides. Importers and exporters are plain functions; every other kind is a
``factory(**options)`` that builds the working object, so that heavy imports (torch, models)
happen only when a command actually uses the component.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover
    from .asset import RiggedAsset

KINDS = (
    "importer",
    "exporter",
    "embedder",
    "renderer",
    "articulation_model",
    "motion_prior",
    "segmenter",
    "flow_estimator",
    "executor",
)


@dataclass(frozen=True)
class ImporterSpec:
    """Reads a file (or folder) into a `RiggedAsset`.

    ``load(path, name)`` returns a validated asset; it raises `zooctl.errors.InputError` for input it
    cannot read. ``suffixes`` are lower-case with the dot (``(".glb", ".gltf")``).
    """

    name: str
    suffixes: tuple[str, ...]
    load: Callable[[Path, str], RiggedAsset]
    description: str = ""
    kind: str = field(default="importer", init=False)


@dataclass(frozen=True)
class ExporterSpec:
    """Writes a `RiggedAsset` to a file.

    ``save(asset, path, clips, **options)`` writes ``path`` (choosing the container from its
    suffix where the format has several), with the named ``clips`` (``None``: all clips).
    ``formats`` are the ``--format`` values it serves (``("usd", "usda", "usdz")``).
    """

    name: str
    formats: tuple[str, ...]
    save: Callable[..., None]
    description: str = ""
    kind: str = field(default="exporter", init=False)


@dataclass(frozen=True)
class ComponentSpec:
    """Any other component: a named factory of a working object.

    ``kind`` is one of `KINDS`; the object ``factory(**options)`` returns follows the interface
    that the kind's hook documents in `zooctl.hookspecs`.
    """

    kind: str
    name: str
    factory: Callable[..., Any]
    description: str = ""

    def __post_init__(self) -> None:
        if self.kind not in KINDS or self.kind in ("importer", "exporter"):
            raise ValueError(f"ComponentSpec kind must be one of {KINDS[2:]}, not {self.kind!r}")

    def create(self, **options: Any) -> Any:
        return self.factory(**options)
