"""`zooctl view --animate DIR`: the motions `zooctl animate` sampled into DIR (its ``animate.json``
and GLBs), side by side with a real clip of the same character, all playing on one clock."""

from __future__ import annotations

import base64
import json
from pathlib import Path
from typing import Any

from zooctl.errors import InputError, UsageError


def load_animate(store: Path, folder: Path) -> dict[str, Any]:
    """The manifest of ``folder``, each sample's GLB, and the real clip: the character's own
    clip (a bank asset's first clip, or a fit's motion from its video) as a GLB."""
    folder = Path(folder)
    manifest_p = folder / "animate.json"
    if not manifest_p.is_file():
        raise InputError(
            f"{folder} holds no animate.json", hint="give the --out folder of a `zooctl animate` run"
        )
    try:
        manifest = json.loads(manifest_p.read_text())
        glbs = [Path(p) for p in manifest["files"]["glb"]]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise InputError(
            f"{manifest_p}: not an animate manifest with GLB files ({exc})",
            hint="animate writes GLBs unless --formats leaves glb out: run it again with glb",
        ) from None
    samples = []
    for i, p in enumerate(glbs):
        p = p if p.is_file() else folder / p.name  # a folder moved since: its files beside the manifest
        if not p.is_file():
            raise InputError(f"{p.name}, listed in {manifest_p}, is missing")
        amp = manifest.get("amplitude_deg") or []
        samples.append(
            {"title": p.stem, "amplitude_deg": amp[i] if i < len(amp) else None, "glb": p.read_bytes()}
        )
    real = _real_clip(store, manifest.get("target"))
    return {"manifest": manifest, "samples": samples, "real": real}


def _real_clip(store: Path, target: str | None) -> dict[str, Any] | None:
    """The target character's own motion as a GLB: a fit's ``fit`` clip, a bank asset's first."""
    if not target:
        return None
    from zooctl.errors import NotFoundError
    from zooctl.io.gltf_export import glb_bytes, gltf_document
    from zooctl.pipelines.animate import resolve_target

    try:
        asset, kind = resolve_target(store, target)
    except NotFoundError:
        return None  # the character is gone from the store: the samples alone
    clip = "fit" if "fit" in asset.clips else next(iter(asset.clips), None)
    if clip is None:
        return None
    source = f"the fit's motion from its video ({target})" if clip == "fit" else f"{target}'s clip {clip!r}"
    return {"title": f"real: {clip}", "source": source, "glb": glb_bytes(*gltf_document(asset, [clip]))}


def write_animate_site(data: dict[str, Any], out: Path) -> Path:
    from .site import start_site, write_data, write_index

    if not data["samples"]:
        raise UsageError("the animate folder lists no sampled motions")
    start_site(out, "animate", {"kind": "animate", "samples": len(data["samples"])})
    panels = ([data["real"]] if data["real"] else []) + data["samples"]
    m = data["manifest"]
    write_data(
        out,
        {
            "kind": "animate",
            "target": m.get("target"),
            "prior": m.get("prior"),
            "temperature": m.get("temperature"),
            "seed": m.get("seed"),
            "panels": [
                {
                    "title": p["title"],
                    "real": p is data["real"],
                    "note": p.get("source")
                    or (
                        f"amplitude {p['amplitude_deg']:.1f} deg"
                        if p.get("amplitude_deg") is not None
                        else ""
                    ),
                    "glb": base64.b64encode(p["glb"]).decode("ascii"),
                }
                for p in panels
            ],
        },
    )
    return write_index(out, "animate")
