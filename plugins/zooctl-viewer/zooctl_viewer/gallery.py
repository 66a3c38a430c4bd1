"""The bank as a gallery: a turntable of every asset (rendered by zooctl's preview renderer) and
its GLB with all clips, to play in the page.

Turntables and GLBs are cached per asset under ``$ZOOCTL_VIEWER_CACHE`` (default
``$XDG_CACHE_HOME/zooctl/viewer``), keyed by the digest of the asset's bank entry: an asset that is
re-added gets new ones, a second `zooctl view --bank` renders only what changed.
"""

from __future__ import annotations

import base64
import io
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from zooctl.errors import UsageError
from zooctl.store.fs import write_bytes_atomic

TURN_VIEWS = 12  # frames of a turntable, 30 degrees apart
TILE = 128  # pixels of one turntable frame
ELEVATION = 15.0


@dataclass
class GalleryEntry:
    name: str
    info: dict[str, Any]  # what the tile shows and filters on
    turntable: bytes  # JPEG, TURN_VIEWS frames of TILE x TILE side by side
    glb: bytes


def cache_dir() -> Path:
    env = os.environ.get("ZOOCTL_VIEWER_CACHE")
    if env:
        return Path(env).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "zooctl" / "viewer"


def load_gallery(store: Path, tags: list[str], progress: Any = None) -> list[GalleryEntry]:
    """Every asset of the bank (with all of ``tags``), its turntable and GLB. ``progress(done, total)``."""
    from zooctl.store.bank import Bank
    from zooctl.store.views_h5 import summary_digest

    bank = Bank.open(store)
    rows = [r for r in bank.list() if all(t in r.get("tags", []) for t in tags)]
    if not rows:
        if tags:
            raise UsageError(
                f"no asset in the bank has the tag{'s' if len(tags) > 1 else ''} {', '.join(tags)}",
                hint="`zooctl bank list` shows the tags",
            )
        raise UsageError("the bank is empty", hint="add the starter animals with `zooctl bank seed`")
    cache = cache_dir()
    out = []
    for i, row in enumerate(rows):
        name = row["name"]
        digest = summary_digest(row)
        turn_p, glb_p = cache / "turntables" / f"{digest}.jpg", cache / "glb" / f"{digest}.glb"
        if turn_p.is_file() and glb_p.is_file():
            turn, glb = turn_p.read_bytes(), glb_p.read_bytes()
        else:
            asset = bank.get(name)
            turn, glb = turntable(asset), _glb(asset)
            write_bytes_atomic(turn_p, turn)
            write_bytes_atomic(glb_p, glb)
        out.append(GalleryEntry(name, _info(bank, row), turn, glb))
        if progress is not None:
            progress(i + 1, len(rows))
    return out


def _info(bank: Any, row: dict[str, Any]) -> dict[str, Any]:
    try:
        meta = bank.card(row["name"]).get("meta", {})
    except Exception:  # an unreadable card: the tile shows what the index has
        meta = {}
    return {
        "name": row["name"],
        "label": row.get("label"),
        "body_plan": meta.get("body_plan"),
        "tags": list(row.get("tags", [])),
        "clips": row.get("clips", {}),
        "vertices": row.get("vertices"),
        "joints": row.get("joints"),
        "license": row.get("license"),
        "source": row.get("source"),
    }


def turntable(asset: Any) -> bytes:
    """JPEG of the asset's rest pose from TURN_VIEWS azimuths around it, side by side."""
    import torch
    from PIL import Image

    from zooctl.render.camera import Camera
    from zooctl.render.preview import PreviewRenderer, fit_camera

    v = asset.pose(None)
    cams = [fit_camera(v, TILE, TILE, az, ELEVATION) for az in np.arange(TURN_VIEWS) * 360.0 / TURN_VIEWS]
    cam = Camera(
        torch.cat([c.intrinsics for c in cams]),
        torch.cat([c.rotation for c in cams]),
        torch.cat([c.translation for c in cams]),
        TILE,
        TILE,
    )
    views = PreviewRenderer(supersample=2).render(
        np.repeat(v[None], TURN_VIEWS, 0), asset.faces, cam, asset.vertex_colors
    )
    strip = np.concatenate(list(views), axis=1)
    buf = io.BytesIO()
    Image.fromarray(strip).save(buf, format="JPEG", quality=85)
    return buf.getvalue()


def _glb(asset: Any) -> bytes:
    from zooctl.io.gltf_export import glb_bytes, gltf_document

    return glb_bytes(*gltf_document(asset, None))


def write_bank_site(entries: list[GalleryEntry], out: Path, tags: list[str], progress: Any = None) -> Path:
    """The gallery in ``out``: turntables as JPEGs, each GLB as a script the page loads when its
    asset is opened. Returns ``out/index.html``."""
    from .site import remove_stale, start_site, write_data, write_index

    start_site(out, "bank", {"kind": "bank", "assets": len(entries)})
    assets = []
    for i, e in enumerate(entries):
        key = f"{i:05d}"
        write_bytes_atomic(out / "turntables" / f"{key}.jpg", e.turntable)
        script = f"ZOOCTL_ASSET({json.dumps(key)}, {json.dumps(base64.b64encode(e.glb).decode('ascii'))});\n"
        write_bytes_atomic(out / "assets" / f"{key}.js", script.encode())
        assets.append(dict(e.info, key=key, turntable=f"turntables/{key}.jpg", glb=f"assets/{key}.js"))
        if progress is not None:
            progress(i + 1, len(entries))
    remove_stale(out / "turntables", {f"{a['key']}.jpg" for a in assets})
    remove_stale(out / "assets", {f"{a['key']}.js" for a in assets})
    write_data(out, {"kind": "bank", "tags_required": tags, "turn_views": TURN_VIEWS, "assets": assets})
    return write_index(out, "bank")
