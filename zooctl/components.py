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
    ``formats`` are the ``--format`` values it serves (``("usd", "usda", "usdz")``) and
    ``suffixes`` the file suffix of each, in the same order (default: ``"." + format``); every
    export command resolves paths and formats through them (`zooctl.io.asset_export.export_asset`).
    ``preload()``, optional, imports what ``save`` needs (a heavy library) ahead of the first file:
    `zooctl.io.export_worker` calls it in its process while the command does other work.
    """

    name: str
    formats: tuple[str, ...]
    save: Callable[..., None]
    description: str = ""
    suffixes: tuple[str, ...] = ()
    preload: Callable[[], None] | None = None
    kind: str = field(default="exporter", init=False)

    def __post_init__(self) -> None:
        formats = tuple(f.lower() for f in self.formats)
        suffixes = tuple(s.lower() for s in self.suffixes) or tuple("." + f for f in formats)
        if len(suffixes) != len(formats) or not all(s.startswith(".") for s in suffixes):
            raise ValueError(f"exporter {self.name!r}: one suffix with a dot per format, got {suffixes}")
        object.__setattr__(self, "formats", formats)
        object.__setattr__(self, "suffixes", suffixes)

    def suffix_for(self, fmt: str) -> str:
        """The file suffix (with the dot) of one of this exporter's formats."""
        return self.suffixes[self.formats.index(fmt.lower())]


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
