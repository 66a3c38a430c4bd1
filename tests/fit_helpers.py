"""Small fits for tests: a config that fits in a few seconds, a rendered procedural animal with the
end-to-end fits' small config, and a video written as a DAVIS folder."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from zooctl.fit.config import FitConfig, preset

# The end-to-end fits' config: 10 frames at 64 px, short stages, about a minute on a CPU.
SMALL = {
    "fit_size": 64,
    "stage1": {"iters": 12, "batch": 10},
    "stage2": {"iters": 16, "batch": 5},
    "camera": {"azimuths": 8, "elevations": [0.0, 25.0]},
}


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


def small_quadruped_video(root: Path) -> tuple[Path, Path, Path]:
    """(store, video folder, config file) under ``root``: a bank holding the procedural quadruped,
    a 10-frame 96 px `bench make` video of it and `SMALL` as a ``--config`` file."""
    from zooctl.benchdata.make import make_video
    from zooctl.procedural import build_animal
    from zooctl.store.bank import Bank

    store = root / "store"
    asset = build_animal("quadruped", name="quadruped")
    Bank(store).add(asset)
    folder = make_video(asset, root / "videos", frames=10, size=96, seed=3)
    cfg = root / "small.json"
    cfg.write_text(json.dumps(SMALL))
    return store, folder, cfg


def write_davis_folder(folder: Path, frames: np.ndarray, masks: np.ndarray) -> Path:
    """Frames (T, H, W, 3) uint8 as JPEGImages/*.jpg and masks (T, H, W) bool as Annotations/*.png."""
    from PIL import Image

    (folder / "JPEGImages").mkdir(parents=True)
    (folder / "Annotations").mkdir()
    for i, (f, m) in enumerate(zip(frames, masks, strict=True)):
        Image.fromarray(f).save(folder / "JPEGImages" / f"{i:05d}.jpg", quality=95)
        Image.fromarray((m * 255).astype(np.uint8)).save(folder / "Annotations" / f"{i:05d}.png")
    return folder
