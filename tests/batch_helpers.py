"""Small inputs for batch tests: tiny benchmark videos with their bank assets, and glb files."""

from __future__ import annotations

from pathlib import Path

from zooctl.benchdata.make import make_video
from zooctl.fit.config import FitConfig, preset
from zooctl.rig.synthetic import tube_asset
from zooctl.store.bank import Bank

# A fit of a few seconds: 3 frames of 32 px, 2 iterations per stage, 4 camera candidates.
TINY = {
    "fit_size": 32,
    "stage1": {"iters": 2, "batch": 4},
    "stage2": {"iters": 2, "batch": 3},
    "camera": {"azimuths": 4, "elevations": [10.0], "search_size": 32},
}


def tiny_config() -> dict:
    return FitConfig.from_dict(TINY, preset("fast")).to_dict()


def fit_inputs(tmp: Path, store: Path, n: int) -> list[str]:
    """``n`` benchmark videos (animals a0, a1, ...), each animal also in the bank."""
    out = []
    for i in range(n):
        asset = tube_asset(bones=2 + i % 2, name=f"a{i}")
        Bank(store).add(asset)
        out.append(str(make_video(asset, tmp / "videos", frames=3, size=32, seed=i)))
    return out


def glb_files(tmp: Path, n: int) -> list[Path]:
    from zooctl.plugins import get_registry

    save = get_registry().exporter_for("glb").save
    paths = []
    for i in range(n):
        p = tmp / "models" / f"m{i}.glb"
        p.parent.mkdir(parents=True, exist_ok=True)
        save(tube_asset(bones=2 + i % 2, name=f"m{i}"), p)
        paths.append(p)
    return paths


def fit_records(store: Path) -> dict[str, dict]:
    from zooctl.store.fits import FitStore

    return {r["name"]: r for r in FitStore(store).list()}


def temporaries(store: Path) -> list[Path]:
    """Files a writer left half-done (atomic writes publish by rename; none must remain)."""
    return [p for p in store.rglob("*.tmp*")]
