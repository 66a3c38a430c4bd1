"""Small inputs for batch tests: tiny benchmark videos with their bank assets, and glb files."""

from __future__ import annotations

from pathlib import Path

from fit_helpers import tiny_fit_config

from zooctl.benchdata.make import make_video
from zooctl.rig.synthetic import tube_asset
from zooctl.store.bank import Bank


def tiny_config() -> dict:
    """A fit of a few seconds (3 frames of 32 px with `fit_inputs`), as a config dict."""
    return tiny_fit_config().to_dict()


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
