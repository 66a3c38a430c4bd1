"""Where a fit's focal length comes from, and what the fit says about it.

In order: ``camera.focal`` (``--focal PX``); ``camera.lens_35mm`` (``--lens MM``); the video's
own intrinsics (a `zooctl bench make` folder); the lens the stored video records
(`zooctl.video.lens`: ``video add --lens``, iPhone QuickTime metadata, Exif); else a guess
(``camera.focal_guess``): a normal lens (``normal``, the default), or the camera search's pick
among ``camera.fov_candidates`` (``search``).

Silhouettes hardly tell lenses apart: a body stretched along the camera's axis by k, seen through
a focal k times longer, casts the same image, and the fit's stretchable bones and displacement
field can make that body. The camera search's rest-pose IoU varies by about 0.01-0.03 across
fields of view of 20 to 80 degrees, and its pick is as often too long as too short
(BENCHMARKS.md, "The focal"). A normal lens, the one photographers call neither wide nor long,
has a focal equal to its frame's diagonal (43 mm on a 36 x 24 mm frame): the middle of the
lenses animals are filmed with (a phone's main camera about 26-30 mm in video, zoomed wildlife
footage far longer), and the same for portrait and landscape frames.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .config import FitConfig
    from .inputs import FitVideo


def resolve_focal(cfg: FitConfig, video: FitVideo) -> tuple[FitConfig, dict[str, Any]]:
    """``cfg`` with ``camera.focal`` set from a known lens or the normal-lens guess (a copy; the
    caller's stays as it is), and where the focal comes from: ``{"from": "given" | "video" | "lens"
    | "normal" | "estimated", "px": focal in pixels of the input frames}`` (no ``px`` for
    ``estimated``, which the camera search finds later), with ``"lens"`` for a lens (the dict of
    `zooctl.video.lens.read_lens`; ``from: config`` for ``camera.lens_35mm``)."""
    from ..video.lens import focal_pixels

    cam = cfg.camera
    if cam.focal is not None:
        return cfg, {"from": "given", "px": float(cam.focal)}
    lens = video.lens
    if cam.lens_35mm is not None:
        lens = {"focal_35mm": float(cam.lens_35mm), "lens_model": None, "from": "config"}
    elif video.intrinsics is not None:
        return cfg, {"from": "video", "px": float(video.intrinsics[0])}
    H, W = video.size
    if lens is not None:
        focal = {"from": "lens", "lens": dict(lens), "px": focal_pixels(float(lens["focal_35mm"]), W, H)}
    elif cam.focal_guess == "normal":
        focal = {"from": "normal", "px": math.hypot(W, H)}
    else:
        return cfg, {"from": "estimated"}
    return dataclasses.replace(cfg, camera=dataclasses.replace(cam, focal=focal["px"])), focal


def lens_note(focal: dict[str, Any]) -> str | None:
    """The note of a fit whose focal came from a lens (`resolve_focal`'s second value), else None."""
    if focal.get("from") != "lens":
        return None
    from ..video.lens import lens_line

    return f"focal {focal['px']:.0f} px from the {lens_line(focal['lens'])}"


def guessed_note(focal: dict[str, Any], height: int) -> str | None:
    """The note of a fit whose focal was guessed (`resolve_focal`'s second value; ``height``: the
    frames' in pixels), else None."""
    if focal.get("from") == "normal":
        what = "a normal lens's, 43 mm 35 mm-equivalent (the frame's diagonal)"
    elif focal.get("from") == "estimated":
        what = "estimated from the silhouettes"
    else:
        return None
    fov = math.degrees(2 * math.atan(0.5 * height / max(focal["px"], 1e-6)))
    return (
        f"no lens was given or recorded: the focal is {what}, {focal['px']:.0f} px (a vertical field of "
        f"view of {fov:.0f} degrees); silhouettes cannot tell lenses apart and a wrong focal stretches the "
        'character front to back (BENCHMARKS.md, "The focal"): if you know the lens, fit again with '
        "--lens MM (its 35 mm-equivalent focal length) or --focal PX (pixels of the input frames)"
    )
