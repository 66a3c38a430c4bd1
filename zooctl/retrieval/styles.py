"""Held-out render styles for retrieval's leave-one-out check: query renders drawn in ways the
bank's views never are (`zooctl.retrieval.views`: the asset's own colours, Lambert shading lit
from the camera's side, elevations -10 to 45 degrees, clean pixels), so a search that wins only
by matching the bank's own rendering shows it.

- ``clay``: one grey albedo for the whole mesh (no colour to match);
- ``toon``: unlit flat colours with a black outline, as cartoon renders draw animals;
- ``recolour``: the asset's colours with their hue turned by a third of the circle;
- ``backlit``: lit from behind the animal, dim ambient (a dark body, bright rims);
- ``below``: seen from 15 to 30 degrees below the horizon;
- ``degraded``: blurred, noisy and JPEG-compressed, as low-quality footage.
"""

from __future__ import annotations

import numpy as np

HELDOUT_STYLES = ("clay", "toon", "recolour", "backlit", "below", "degraded")
CLAY_ALBEDO = 0.55


def check_style(style: str | None) -> None:
    if style is not None and style not in HELDOUT_STYLES:
        raise ValueError(f"unknown render style {style!r}: one of {', '.join(HELDOUT_STYLES)}")


def style_colors(colors: np.ndarray, style: str | None) -> np.ndarray:
    """(V, 3) linear albedo of a query render in ``style``."""
    if style == "clay":
        return np.full_like(np.asarray(colors, np.float32), CLAY_ALBEDO)
    if style == "recolour":
        import cv2

        c = np.clip(np.asarray(colors, np.float32), 0, 1) ** (1 / 2.2)
        hsv = cv2.cvtColor(c[None], cv2.COLOR_RGB2HSV)[0]
        hsv[:, 0] = (hsv[:, 0] + 120.0) % 360.0
        return np.clip(cv2.cvtColor(hsv[None], cv2.COLOR_HSV2RGB)[0], 0, 1) ** 2.2
    return np.asarray(colors, np.float32)


def style_elevation(elevation: float, style: str | None) -> float:
    """The camera elevation (degrees) of a query drawn with ``elevation`` in [0, 35)."""
    return -15.0 - 15.0 * elevation / 35.0 if style == "below" else elevation


def style_light(
    light: np.ndarray, rotation: np.ndarray, ambient: float, style: str | None
) -> tuple[np.ndarray, float]:
    """(world light direction, ambient) of a query render: ``backlit`` mirrors the light to the far
    side of the animal (``rotation``: the camera's world-to-camera rotation) and dims the ambient;
    ``toon`` is unlit (ambient 1)."""
    if style == "backlit":
        d = rotation @ light
        d[2] = abs(d[2]) + 0.3  # away from the camera (it looks down +Z)
        return rotation.T @ (d / np.linalg.norm(d)), 0.08
    if style == "toon":
        return light, 1.0
    return light, ambient


def style_pixels(rgb: np.ndarray, sil: np.ndarray, style: str | None, seed: int = 0) -> np.ndarray:
    """(N, R, R, 3) uint8 frames after the style's drawing: outlines (``toon``), or blur, noise and
    JPEG compression (``degraded``)."""
    import cv2

    if style == "toon":
        out = rgb.copy()
        kernel = np.ones((5, 5), np.uint8)
        for i in range(len(out)):
            m = sil[i].astype(np.uint8)
            edge = cv2.dilate(m, kernel) != cv2.erode(m, kernel)
            out[i][edge] = 20
        return out
    if style == "degraded":
        rng = np.random.default_rng(seed)
        out = np.empty_like(rgb)
        for i in range(len(rgb)):
            img = cv2.GaussianBlur(rgb[i], (0, 0), 1.6).astype(np.float32)
            img = np.clip(img + rng.normal(0, 8, img.shape), 0, 255).astype(np.uint8)
            ok, buf = cv2.imencode(".jpg", img[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 25])
            out[i] = cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1] if ok else img
        return out
    return rgb
