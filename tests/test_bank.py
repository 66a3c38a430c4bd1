"""The asset bank through the real CLI: add, list, show, rm, errors, schema of what is written."""

from __future__ import annotations

import json
import shutil

import jsonschema
import numpy as np
import pytest
from cli_helpers import REPO, zooctl
from conftest import needs_shared_assets, shared_assets
from gltf_builder import glb_bytes, tiny_gltf, write_tiny_glb

from zooctl.errors import AlreadyExistsError, NotFoundError, StoreError
from zooctl.io.gltf_import import load_gltf
from zooctl.store.asset_h5 import SCHEMA_VERSION, Migration, migrate_file, read_asset
from zooctl.store.bank import Bank
from zooctl.store.h5 import describe_h5


def schema(name):
    return json.loads((REPO / "schemas" / f"{name}.schema.json").read_text())


def snapshot(root):
    """Every file under the store with its bytes: 'unchanged' means byte-identical."""
    return {
        str(p.relative_to(root)): p.read_bytes()
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.name != ".lock"
    }


@needs_shared_assets
def test_all_shared_assets_enter_the_bank_and_list_json_reports_counts(tmp_path):
    store = tmp_path / "store"
    paths = [str(p) for p in shared_assets()]
    r = zooctl("bank", "add", *paths, "--tag", "quaternius", "--license", "CC0-1.0", store=store)
    assert r.code == 0, r.err
    rows = zooctl("bank", "list", "--json", store=store).json()
    assert len(rows) == 28
    by_name = {row["name"]: row for row in rows}
    fox = load_gltf(shared_assets()[[p.stem for p in shared_assets()].index("Fox")], "Fox")
    assert by_name["Fox"]["joints"] == fox.num_joints and by_name["Fox"]["vertices"] == fox.num_vertices
    assert all(row["tags"] == ["quaternius"] and row["license"] == "CC0-1.0" for row in rows)
    # what the code wrote validates against the published schemas
    bank = Bank(store)
    jsonschema.validate(json.loads(bank.index_path.read_text()), schema("bank_index"))
    for name in ("Fox", "Wasp", "Character"):
        jsonschema.validate(describe_h5(bank.asset_path(name)), schema("asset_h5"))
        jsonschema.validate(json.loads(bank.card_path(name).read_text()), schema("asset_card"))
    # stored assets read back identical to a fresh import
    back = bank.get("Fox")
    np.testing.assert_array_equal(back.vertices, fox.vertices.astype(np.float32))
    np.testing.assert_allclose(
        back.pose("AnimalArmature|Walk", 7), fox.pose("AnimalArmature|Walk", 7), atol=1e-6
    )
    show = zooctl("bank", "show", "Fox", "--json", store=store).json()
    assert show["joint_names"][: len(fox.joint_names)] == fox.joint_names and len(show["clips"]) == len(
        fox.clips
    )
    table = zooctl("bank", "show", "Fox", store=store)
    assert table.code == 0 and "Tail4" in table.out and "AnimalArmature|Walk" in table.out


def test_add_list_show_rm_replace(tmp_path):
    store = tmp_path / "s"
    f = write_tiny_glb(tmp_path / "tiny.glb")
    assert zooctl("bank", "add", str(f), "--name", "worm", "--tag", "test", store=store).code == 0
    r = zooctl("bank", "list", store=store)
    assert r.code == 0 and "worm" in r.out
    dup = zooctl("bank", "add", str(f), "--name", "worm", store=store)
    assert dup.code == 2 and "already in the bank" in dup.err and "--replace" in dup.err
    assert "Traceback" not in dup.err
    assert zooctl("bank", "add", str(f), "--name", "worm", "--replace", store=store).code == 0
    card = zooctl("bank", "show", "worm", "--json", store=store).json()
    assert card["joint_names"] == ["root", "tip"] and card["clips"]["bend"]["frames"] == 31
    missing = zooctl("bank", "show", "wrom", store=store)
    assert missing.code == 2 and "did you mean worm" in missing.err
    assert zooctl("bank", "rm", "worm", store=store).code == 0
    assert zooctl("bank", "list", "--json", store=store).json() == []
    assert not list((store / "bank" / "assets").glob("worm*"))
    empty = zooctl("bank", "list", store=store)  # a table of nothing says how to fill the bank
    assert empty.code == 0 and "the bank is empty" in empty.out and "zooctl bank seed" in empty.out


BAD = {
    "empty": lambda d: (d / "empty.glb").write_bytes(b"") or d / "empty.glb",
    "truncated": lambda d: (d / "trunc.glb").write_bytes(glb_bytes(*tiny_gltf())[:-60]) or d / "trunc.glb",
    "missing_bin": lambda d: _missing_bin(d),
    "no_skin": lambda d: write_tiny_glb(d / "noskin.glb", skin=False),
    "nan_weights": lambda d: write_tiny_glb(d / "nan.glb", weights=[[np.nan, 0, 0, 0]] * 4),
    "negative_weights": lambda d: write_tiny_glb(d / "neg.glb", weights=[[1.5, -0.5, 0, 0]] * 4),
    "joint_out_of_range": lambda d: write_tiny_glb(d / "range.glb", joints=[[9, 0, 0, 0]] * 4),
    "unknown_suffix": lambda d: (d / "model.xyz").write_text("hello") or d / "model.xyz",
    "directory": lambda d: (d / "folder.glb").mkdir() or d / "folder.glb",
    "does_not_exist": lambda d: d / "nope.glb",
}


def _missing_bin(d):
    doc, _ = tiny_gltf()
    doc["buffers"][0]["uri"] = "gone.bin"
    (d / "nobin.gltf").write_text(json.dumps(doc))
    return d / "nobin.gltf"


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_is_one_clear_line_and_leaves_the_bank_unchanged(tmp_path, case):
    store = tmp_path / "s"
    good = write_tiny_glb(tmp_path / "good.glb")
    assert zooctl("bank", "add", str(good), store=store).code == 0
    before = snapshot(store)
    bad = BAD[case](tmp_path)
    r = zooctl("bank", "add", str(bad), store=store)
    assert r.code == 2, (r.out, r.err)
    assert r.err.startswith("error: ") and "Traceback" not in r.err
    assert len([ln for ln in r.err.splitlines() if ln.startswith("error:")]) == 1
    assert snapshot(store) == before


def test_existing_name_in_a_batch_fails_alone(tmp_path):
    store = tmp_path / "s"
    a = write_tiny_glb(tmp_path / "a.glb")
    b = write_tiny_glb(tmp_path / "b.glb")
    assert zooctl("bank", "add", str(a), store=store).code == 0
    r = zooctl("bank", "add", str(a), str(b), store=store)
    assert r.code == 2 and "1 of 2 files were not added" in r.err
    assert sorted(x["name"] for x in zooctl("bank", "list", "--json", store=store).json()) == ["a", "b"]


def test_debug_env_shows_the_traceback(tmp_path):
    r = zooctl("bank", "show", "nothing", store=tmp_path / "s", env={"ZOOCTL_DEBUG": "1"})
    assert r.code == 2 and "Traceback" in r.err and "error: no asset named" in r.err


def test_library_errors_and_versions(tmp_path):
    bank = Bank(tmp_path)
    asset = load_gltf(write_tiny_glb(tmp_path / "t.glb"), "t")
    bank.add(asset)
    with pytest.raises(AlreadyExistsError):
        bank.add(asset)
    with pytest.raises(NotFoundError):
        bank.get("u")
    import h5py

    with h5py.File(bank.asset_path("t"), "r+") as f:
        f.attrs["schema_version"] = SCHEMA_VERSION + 1
    with pytest.raises(StoreError, match="newer zooctl"):
        bank.get("t")


def test_named_migrations_apply_in_order(tmp_path):
    import h5py

    bank = Bank(tmp_path)
    bank.add(load_gltf(write_tiny_glb(tmp_path / "t.glb"), "t"))
    path = bank.asset_path("t")
    copy = tmp_path / "copy.h5"
    shutil.copyfile(path, copy)
    with h5py.File(copy, "r+") as f:  # pretend it is a layout-0 file that lacked /mesh/faces' int32
        f.attrs["schema_version"] = 0
        f.attrs.pop("name")

    def restore_name(f):
        f.attrs["name"] = "t"

    applied = migrate_file(copy, [Migration("0001_add_name_attr", 0, restore_name)])
    assert applied == ["0001_add_name_attr"]
    assert read_asset(copy).name == "t"
    with h5py.File(copy, "r+") as f:
        f.attrs["schema_version"] = 0
    with pytest.raises(StoreError, match="no migration path"):
        migrate_file(copy, [])
