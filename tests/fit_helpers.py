"""Small fits for tests: a config that fits in a few seconds, and a video written as a DAVIS folder."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from zooctl.fit.config import FitConfig, preset


def tiny_overrides(iters: int = 2) -> dict:
    """Config overrides for a fit of a few seconds: 32 px, ``iters`` iterations a stage, 4 camera
    candidates (a new dict each call: configs may keep and change it)."""
    return {
        "fit_size": 32,
        "stage1": {"iters": iters, "batch": 4},
        "stage2": {"iters": iters, "batch": 3},
        "camera": {"azimuths": 4, "elevations": [10.0], "search_size": 32},
    }


def tiny_fit_config(iters: int = 2) -> FitConfig:
    """The fast preset with `tiny_overrides`."""
    return FitConfig.from_dict(tiny_overrides(iters), preset("fast"))


def write_davis_folder(folder: Path, frames: np.ndarray, masks: np.ndarray) -> Path:
    """Frames (T, H, W, 3) uint8 as JPEGImages/*.jpg and masks (T, H, W) bool as Annotations/*.png."""
    from PIL import Image

    (folder / "JPEGImages").mkdir(parents=True)
    (folder / "Annotations").mkdir()
    for i, (f, m) in enumerate(zip(frames, masks, strict=True)):
        Image.fromarray(f).save(folder / "JPEGImages" / f"{i:05d}.jpg", quality=95)
        Image.fromarray((m * 255).astype(np.uint8)).save(folder / "Annotations" / f"{i:05d}.png")
    return folder
