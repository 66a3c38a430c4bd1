"""`export_asset`: the one way every command writes an asset through an exporter plugin.

Formats and file suffixes come from the registered `zooctl.components.ExporterSpec`s, so a
plugin's exporter works in ``bank export``, ``fits export`` and ``animate`` alike. Paths follow one
rule: an existing folder gets ``NAME`` plus the format's suffix inside it, a path without a suffix
gets the suffix added, and a suffix that disagrees with ``--format`` is an error.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from ..asset import RiggedAsset
from ..components import ExporterSpec
from ..errors import StoreError, UsageError


def export_formats() -> list[str]:
    """Every ``--format`` value some registered exporter serves."""
    from ..plugins import get_registry

    return sorted(f for spec in get_registry().components["exporter"].values() for f in spec.formats)


def _exporter_for_suffix(suffix: str) -> tuple[ExporterSpec, str] | None:
    from ..plugins import get_registry

    for spec in get_registry().components["exporter"].values():
        if suffix.lower() in spec.suffixes:
            return spec, spec.formats[spec.suffixes.index(suffix.lower())]
    return None


def resolve_export(
    path: str | Path | None, fmt: str | None, name: str, default_format: str | None = None
) -> tuple[ExporterSpec, str, Path]:
    """(exporter, format, file path) for ``-o path`` and ``--format fmt``; each defaults from the
    other (module docstring), then ``default_format``. A ``path`` string ending in a slash names a
    folder even before it exists. Raises `UsageError` saying what to change."""
    from ..plugins import get_registry

    slash = isinstance(path, str) and path.endswith(("/", os.sep))
    path = None if path is None else Path(path)
    if path is not None:
        check_not_special(path)  # before a suffix is added: `-o /dev/full` is not /dev/full.usdz
    is_dir = path is not None and (slash or path.is_dir())
    if fmt is None and path is not None and path.suffix and not is_dir:
        found = _exporter_for_suffix(path.suffix)
        if found is None:
            raise UsageError(
                f"cannot tell an export format from {path.name!r}",
                hint=f"use --format with one of {', '.join(export_formats())}",
            )
        fmt = found[1]
    fmt = (fmt or default_format or "").lower()
    if not fmt:
        raise UsageError(
            "no export format given", hint=f"use --format with one of {', '.join(export_formats())}"
        )
    spec = get_registry().exporter_for(fmt)
    if spec is None:
        raise UsageError(
            f"unknown export format {fmt!r}",
            hint=f"formats: {', '.join(export_formats())} (exporters come from plugins: `zooctl plugins`)",
        )
    suffix = spec.suffix_for(fmt)
    if path is None:
        path = Path(name + suffix)
    elif is_dir:
        path = path / (name + suffix)
    elif path.suffix == "":
        path = path.with_name(path.name + suffix)
    elif path.suffix.lower() != suffix:
        raise UsageError(
            f"--format {fmt} writes {suffix} files, but the output is {path.name!r}",
            hint=f"name the output *{suffix} or pick the format that matches it",
        )
    return spec, fmt, path


def check_not_special(path: Path) -> None:
    """A `UsageError` when ``path`` exists but is neither a regular file nor a folder: writing to a
    device or a FIFO would vanish, fail late or block (after symlinks: a link to one counts too)."""
    import stat

    try:
        mode = path.stat().st_mode
    except OSError:  # absent (or unreachable): the writer says what is wrong with it
        return
    if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
        raise UsageError(
            f"{path} is not a regular file or a folder (a device, FIFO or socket)",
            hint="give a file name in a folder, or an existing folder",
        )


def prepare_export(
    out: str | None, fmt: str | None, name: str, default_format: str | None = None
) -> tuple[ExporterSpec, str, Path]:
    """`resolve_export` for a CLI's ``-o``/``--out``, then the folder a path ending in a slash names
    made (the help promises it), then `check_writable`."""
    spec, fmt, path = resolve_export(out, fmt, name, default_format)
    if isinstance(out, str) and out.endswith(("/", os.sep)) and not path.parent.exists():
        check_not_special(path.parent)
        try:
            path.parent.mkdir(parents=True)
        except OSError as exc:
            raise UsageError(
                f"cannot make the folder {path.parent}: {exc.strerror}", hint="choose another -o"
            ) from None
    check_writable(path)
    return spec, fmt, path


def check_writable(path: Path) -> None:
    """A clear `UsageError` when ``path``'s folder is missing or cannot be written, or ``path`` is
    something a file cannot be written to."""
    check_not_special(path)
    parent = path.parent
    if not parent.is_dir():
        raise UsageError(f"the folder {parent} does not exist", hint="create it first")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise UsageError(f"cannot write to the folder {parent}: permission denied", hint="choose another -o")
    if path.is_dir():
        raise UsageError(f"{path} is a folder", hint="give a file name")


def export_asset(
    asset: RiggedAsset, path: Path | None, fmt: str | None = None, clips: list[str] | None = None, **opts: Any
) -> Path:
    """Write ``asset`` (the named ``clips``, or all) through the exporter of ``fmt`` (default: from
    the path's suffix); ``path`` may be a folder (``asset.name`` + suffix inside it). ``opts`` go to
    the exporter (e.g. ``camera`` for USD). Returns the file written."""
    spec, fmt, path = resolve_export(path, fmt, asset.name)
    return write_export(spec, asset, path, clips, **opts)


def write_export(
    spec: ExporterSpec, asset: RiggedAsset, path: Path, clips: list[str] | None = None, **opts: Any
) -> Path:
    """Write ``asset`` to ``path`` (resolved: `resolve_export`) through ``spec``; a folder that
    cannot be written or a full disk is a `UsageError` that says so. Returns ``path``."""
    check_writable(path)
    try:
        spec.save(asset, path, clips, **opts)
    except (OSError, StoreError) as exc:  # a full disk, a read-only mount, a file the OS will not create
        why = exc.message if isinstance(exc, StoreError) else exc.strerror or type(exc).__name__
        raise UsageError(
            f"cannot write {path}: {why}", hint="check the folder's space and permissions"
        ) from None
    return path
