"""HDF5 serialisation of a `RiggedAsset` (layout: ``schemas/asset_h5.schema.json``).

::

    /                       attrs: zooctl_kind="asset", schema_version, name, meta (JSON)
    /mesh/vertices          (V, 3) float32, bind space
    /mesh/faces             (F, 3) int32
    /mesh/uvs               (V, 2) float32            optional
    /mesh/vertex_colors     (V, 3) float32            optional
    /mesh/texture_png       (N,) uint8, PNG bytes     optional
    /skeleton/joint_names   (J,) utf-8 strings
    /skeleton/parents       (J,) int32
    /skeleton/rest_local    (J, 4, 4) float64
    /skeleton/inverse_bind  (J, 4, 4) float64
    /skin/joints            (V, K) int32
    /skin/weights           (V, K) float32
    /clips/<i>              attrs: name, fps; rotations (T, J, 4), translations (T, J, 3), scales (T, J, 3)
    /views, /embeddings     reserved for retrieval (rendered views and their embeddings)

Clip names may contain any character, so clip groups are numbered and the name is an attribute.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from ..asset import LABEL_KEYS, Clip, RiggedAsset
from ..errors import StoreError
from .h5 import read_h5

SCHEMA_VERSION = 1
_STR = h5py.string_dtype("utf-8")


@dataclass(frozen=True)
class Migration:
    """Upgrades an open asset file in place from ``from_version`` to ``from_version + 1``."""

    name: str
    from_version: int
    apply: Callable[[h5py.File], None]


# Named migrations, applied in order by `migrate_file`. Layout version 1 is the first released
# one, so the list is empty; each future layout change appends one entry here.
MIGRATIONS: list[Migration] = []


def write_asset(path: Path, asset: RiggedAsset) -> None:
    """Write ``asset`` to ``path`` (a temporary the caller publishes), built in memory first so a
    full disk is a clean `NoSpaceError`."""
    from .fs import h5_image, writing

    image = h5_image(lambda f: fill_asset(f, asset), libver="latest")
    with writing(f"writing {path}"):
        Path(path).write_bytes(image)


def fill_asset(f: h5py.File, asset: RiggedAsset) -> None:
    """Write ``asset`` into the open, empty HDF5 file ``f``."""
    f.attrs["zooctl_kind"] = "asset"
    f.attrs["schema_version"] = SCHEMA_VERSION
    f.attrs["name"] = asset.name
    f.attrs["meta"] = json.dumps(asset.meta, default=str)
    m = f.create_group("mesh")
    m.create_dataset("vertices", data=asset.vertices.astype(np.float32))
    m.create_dataset("faces", data=asset.faces.astype(np.int32))
    if asset.uvs is not None:
        m.create_dataset("uvs", data=asset.uvs.astype(np.float32))
    if asset.vertex_colors is not None:
        m.create_dataset("vertex_colors", data=asset.vertex_colors.astype(np.float32))
    if asset.texture_png is not None:
        m.create_dataset("texture_png", data=np.frombuffer(asset.texture_png, dtype=np.uint8))
    s = f.create_group("skeleton")
    s.create_dataset("joint_names", data=np.array(asset.joint_names, dtype=object), dtype=_STR)
    s.create_dataset("parents", data=asset.parents.astype(np.int32))
    s.create_dataset("rest_local", data=asset.rest_local.astype(np.float64))
    s.create_dataset("inverse_bind", data=asset.inverse_bind.astype(np.float64))
    k = f.create_group("skin")
    k.create_dataset("joints", data=asset.skin_joints.astype(np.int32))
    k.create_dataset("weights", data=asset.skin_weights.astype(np.float32))
    c = f.create_group("clips")
    for i, clip in enumerate(asset.clips.values()):
        g = c.create_group(str(i))
        g.attrs["name"] = clip.name
        g.attrs["fps"] = float(clip.fps)
        for key in ("rotations", "translations", "scales"):
            g.create_dataset(key, data=getattr(clip, key).astype(np.float32), compression="lzf", shuffle=True)


def read_asset(path: Path) -> RiggedAsset:
    hint = "re-add the asset with --replace"

    def read(f: h5py.File) -> RiggedAsset:
        if f.attrs.get("zooctl_kind") != "asset":
            raise StoreError(f"{path} is not a zooctl asset file", hint=hint)
        _check_version(f, path)
        return _read(f)

    return read_h5(path, "asset file", hint, read)


def _read(f: h5py.File) -> RiggedAsset:
    m, s, k = f["mesh"], f["skeleton"], f["skin"]
    clips = {}
    for key in sorted(f["clips"], key=int):
        g = f["clips"][key]
        name = str(g.attrs["name"])
        clips[name] = Clip(
            name, float(g.attrs["fps"]), g["rotations"][()], g["translations"][()], g["scales"][()]
        )
    return RiggedAsset(
        name=str(f.attrs["name"]),
        vertices=m["vertices"][()],
        faces=m["faces"][()],
        joint_names=[x.decode() if isinstance(x, bytes) else str(x) for x in s["joint_names"][()]],
        parents=s["parents"][()],
        rest_local=s["rest_local"][()],
        inverse_bind=s["inverse_bind"][()],
        skin_joints=k["joints"][()],
        skin_weights=k["weights"][()],
        clips=clips,
        uvs=m["uvs"][()] if "uvs" in m else None,
        vertex_colors=m["vertex_colors"][()] if "vertex_colors" in m else None,
        texture_png=m["texture_png"][()].tobytes() if "texture_png" in m else None,
        meta=json.loads(f.attrs.get("meta", "{}")),
    )


def _check_version(f: h5py.File, path: Path) -> None:
    v = int(f.attrs.get("schema_version", 0))
    if v > SCHEMA_VERSION:
        raise StoreError(
            f"{path} was written by a newer zooctl (layout {v}; this one reads {SCHEMA_VERSION})",
            hint="upgrade zooctl",
        )
    if v < SCHEMA_VERSION:
        raise StoreError(
            f"{path} has the old layout {v}", hint="run `zooctl bank migrate` to upgrade the bank"
        )


def pending_migrations(version: int, migrations: list[Migration] | None = None) -> list[Migration]:
    migs = MIGRATIONS if migrations is None else migrations
    out, v = [], version
    for mig in sorted(migs, key=lambda m: m.from_version):
        if mig.from_version == v:
            out.append(mig)
            v += 1
    return out


def migrate_file(
    path: Path, migrations: list[Migration] | None = None, target: int = SCHEMA_VERSION
) -> list[str]:
    """Upgrade a (temporary copy of an) asset file to ``target``; returns the names applied."""
    applied = []
    with h5py.File(path, "r+") as f:
        v = int(f.attrs.get("schema_version", 0))
        for mig in pending_migrations(v, migrations):
            if v >= target:
                break
            mig.apply(f)
            v = mig.from_version + 1
            f.attrs["schema_version"] = v
            applied.append(mig.name)
        if v != target:
            raise StoreError(f"{path}: no migration path from layout {v} to {target}")
    return applied


def card_of(asset: RiggedAsset) -> dict[str, Any]:
    """The asset's card: what `bank show` prints beyond the index summary."""
    return {
        "schema_version": SCHEMA_VERSION,
        "name": asset.name,
        "joint_names": list(asset.joint_names),
        "parents": [int(p) for p in asset.parents],
        "skin_influences": int(asset.skin_joints.shape[1]),
        "meta": json.loads(json.dumps(asset.meta, default=str)),
        **{k: asset.meta[k] for k in LABEL_KEYS if isinstance(asset.meta.get(k), str)},
    }
