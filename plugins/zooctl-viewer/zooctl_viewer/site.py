"""The viewer as a static site: HTML, our scripts, the vendored three.js, and the data.

One layout serves both uses: `zooctl view` writes it to a temporary folder and serves it over
HTTP, `--export DIR` writes it to DIR to open from disk. Pages load everything through classic
``<script src>`` and ``<img src>`` with relative paths (the data as ``data.js``, the GLB inside it as
base64), because browsers refuse ES module imports and ``fetch`` from ``file://`` pages.
"""

from __future__ import annotations

import base64
import io
import json
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from zooctl.errors import UsageError
from zooctl.store.fs import write_bytes_atomic

MARKER = "zooctl-view.json"
MASK_RGBA = (0, 190, 255, 90)  # the fitted masks: translucent cyan
SILHOUETTE_RGBA = (255, 0, 255, 255)  # the reprojected character's outline: magenta, as overlay.mp4
PAGES = {  # page: its title, and whether it draws in 3D (loads the vendored three.js)
    "fit": ("zooctl view", True),
    "bank": ("zooctl view --bank", True),
    "bench": ("zooctl view --bench", False),
    "animate": ("zooctl view --animate", True),
}


def check_out_dir(out: Path) -> None:
    """Refuse to write into a folder that holds something other than an earlier viewer export."""
    if out.exists() and not out.is_dir():
        raise UsageError(f"--export {out}: is a file", hint="give a folder for the site")
    if out.is_dir() and any(out.iterdir()) and not (out / MARKER).is_file():
        raise UsageError(
            f"--export {out}: the folder is not empty and holds no earlier viewer export",
            hint="give a new or empty folder",
        )


def static_files(out: Path) -> None:
    """Copy the pages' scripts (a benchmark table's fit pages use the fit script from its
    folder), the shared script and style, and the vendored three.js (with its licence) into ``out``."""
    root = resources.files("zooctl_viewer") / "static"
    for rel in ("viewer.css", "common.js", "fit.js", "bank.js", "bench.js", "animate.js"):
        write_bytes_atomic(out / rel, (root / rel).read_bytes())
    for rel in ("three.bundle.js", "three.LICENSE", "VERSION"):
        write_bytes_atomic(out / "vendor" / rel, (root / "vendor" / rel).read_bytes())


def write_data(out: Path, data: dict[str, Any]) -> None:
    """``data.js``: the page's data as one global, loadable from disk by a classic script tag."""
    text = "window.ZOOCTL_VIEW = " + json.dumps(data, separators=(",", ":"), allow_nan=False) + ";\n"
    write_bytes_atomic(out / "data.js", text.encode())


def start_site(out: Path, page: str, meta: dict[str, Any], up: str = "") -> None:
    """Claim ``out`` for a viewer site (the marker that lets a later export replace it), then copy
    the static files of ``page``; with ``up`` (a page nested in another site, e.g. ``"../../"``)
    the page uses the enclosing site's scripts instead (`write_index`), only its own are copied."""
    check_out_dir(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "index.html").unlink(missing_ok=True)  # until this export is complete
    write_bytes_atomic(out / MARKER, json.dumps(meta, indent=2).encode())
    if not up:
        static_files(out)


def page_html(page: str, up: str = "") -> str:
    """``page``'s HTML: its body (``static/<page>.html``) in the layout every page shares
    (``static/layout.html``: head, style, error line, scripts). ``up``: the relative path to the
    enclosing site that holds the style and scripts (see `start_site`); the data is the page's own."""
    from string import Template

    root = resources.files("zooctl_viewer") / "static"
    title, three = PAGES[page]
    three_js = [f"{up}vendor/three.bundle.js"] if three else []
    scripts = [*three_js, "data.js", f"{up}common.js", f"{up}{page}.js"]
    return Template((root / "layout.html").read_text()).substitute(
        title=title,
        up=up,
        body=(root / f"{page}.html").read_text(),
        scripts="".join(f'<script src="{s}"></script>\n' for s in scripts),
    )


def write_index(out: Path, page: str, up: str = "") -> Path:
    """``index.html``, ``page``'s HTML (`page_html`): written last, so a folder with an index is a
    complete site."""
    write_bytes_atomic(out / "index.html", page_html(page, up).encode())
    return out / "index.html"


def jpeg(img: np.ndarray, quality: int = 85) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(img)).save(buf, format="JPEG", quality=quality)
    return buf.getvalue()


def overlay_png(mask: np.ndarray, silhouette: np.ndarray) -> bytes:
    """RGBA PNG (H, W): ``mask`` filled in `MASK_RGBA`, the outline of ``silhouette`` in
    `SILHOUETTE_RGBA`, transparent elsewhere; the page lays it over the frame."""
    import cv2
    from PIL import Image

    H = mask.shape[0]
    rgba = np.zeros(mask.shape + (4,), np.uint8)
    rgba[mask] = MASK_RGBA
    contours, _ = cv2.findContours(silhouette.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    cv2.drawContours(rgba, contours, -1, SILHOUETTE_RGBA, max(1, round(H / 160)))
    buf = io.BytesIO()
    Image.fromarray(rgba, "RGBA").save(buf, format="PNG", optimize=False)
    return buf.getvalue()


def remove_stale(folder: Path, keep: set[str]) -> None:
    """Files of an earlier export in ``folder`` that this one did not write (a longer fit's frames)."""
    if folder.is_dir():
        for p in folder.iterdir():
            if p.is_file() and p.name not in keep:
                p.unlink()


def write_fit_site(view: Any, out: Path, progress: Any = None, up: str = "", back: str | None = None) -> Path:
    """The fit viewer for a `zooctl_viewer.fit_data.FitView` in ``out``; returns ``out/index.html``.
    ``progress(done, total)`` after each frame. ``up``: nested in another site (`start_site`);
    ``back``: a link the page shows to where it was opened from."""
    T = len(view.frames)
    start_site(out, "fit", {"kind": "fit", "name": view.name, "frames": T}, up)
    names = [f"{i:05d}" for i in range(T)]
    for i, n in enumerate(names):
        write_bytes_atomic(out / "frames" / f"{n}.jpg", jpeg(view.frames[i]))
        write_bytes_atomic(out / "overlay" / f"{n}.png", overlay_png(view.masks[i], view.silhouettes[i]))
        if progress is not None:
            progress(i + 1, T)
    remove_stale(out / "frames", {f"{n}.jpg" for n in names})
    remove_stale(out / "overlay", {f"{n}.png" for n in names})
    inter = (view.masks & view.silhouettes).sum((1, 2))
    union = (view.masks | view.silhouettes).sum((1, 2))
    iou = [round(float(a) / float(b), 4) if b else None for a, b in zip(inter, union, strict=True)]
    H, W = view.frames.shape[1:3]
    write_data(
        out,
        {
            "kind": "fit",
            "name": view.name,
            "fps": view.fps,
            "frames": T,
            "width": int(W),
            "height": int(H),
            "frame_files": [f"frames/{n}.jpg" for n in names],
            "overlay_files": [f"overlay/{n}.png" for n in names],
            "silhouette_iou": iou,
            "camera": view.camera,
            "record": _jsonable(view.record),
            "glb": base64.b64encode(view.glb).decode("ascii"),
            "back": back,
        },
    )
    return write_index(out, "fit", up)


def _jsonable(obj: Any) -> Any:
    """The record with non-finite numbers as null (JSON has no NaN)."""
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj
