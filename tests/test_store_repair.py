"""A lost or damaged index is never an empty store: commands say so, `clean` deletes no stored
item, `add` never writes an index that drops items, and `repair` rebuilds the index from the files."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import jsonschema
import pytest
from cli_helpers import REPO, run_inprocess
from gltf_builder import write_tiny_glb
from video_helpers import synthetic_video

from zooctl.errors import StoreError
from zooctl.io.gltf_import import load_gltf
from zooctl.store.bank import Bank
from zooctl.store.videos import VideoStore


def validate(instance, name):
    schema = json.loads((REPO / "schemas" / f"{name}.schema.json").read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    jsonschema.validate(instance, schema)


def hashes(root: Path) -> dict[str, int]:
    return {
        str(p.relative_to(root)): hash(p.read_bytes())
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.name != ".lock"
    }


def tiny_bank(root: Path, names=("a", "b", "c")) -> Bank:
    bank = Bank(root)
    for n in names:
        bank.add(load_gltf(write_tiny_glb(root.parent / f"{n}.glb"), n))
    return bank


DAMAGED = [
    ("deleted", None, "is missing"),
    ("empty list", "[]", "damaged"),
    ("empty object", "{}", "damaged"),
    ("no table", '{"schema_version": 1}', "damaged"),
    ("old version", '{"schema_version": 0, "assets": {}}', "damaged"),
    ("garbage", "\x00\x01not json", "damaged"),
    ("truncated", "TRUNC", "damaged"),
    ("entry lacks bbox", "NOBBOX", "lacks 'bbox'"),
    ("entry not a table", "NOTDICT", "not a table"),
]


def _damage_index(path: Path, how: str | None) -> None:
    good = json.loads(path.read_text())
    if how is None:
        path.unlink()
    elif how == "TRUNC":
        path.write_text(path.read_text()[: len(path.read_text()) // 2])
    elif how == "NOBBOX":
        del good["assets"]["b"]["bbox"]
        path.write_text(json.dumps(good))
    elif how == "NOTDICT":
        good["assets"]["b"] = "b"
        path.write_text(json.dumps(good))
    else:
        path.write_text(how)


@pytest.mark.parametrize("case", DAMAGED, ids=[c[0] for c in DAMAGED])
def test_damaged_bank_index_is_an_error_until_repair_and_nothing_is_lost(tmp_path, capsys, case):
    _, how, message = case
    root = tmp_path / "store"
    bank = tiny_bank(root)
    before = {k: v for k, v in hashes(root).items() if not k.endswith("index.json")}
    _damage_index(bank.index_path, how)
    for args in (
        ["bank", "list"],
        ["bank", "show", "a"],
        ["bank", "clean"],
        ["bank", "migrate"],
        ["bank", "rm", "a"],
    ):
        r = run_inprocess(capsys, "--store", str(root), *args)
        assert r.code != 0, args
        assert message in r.err and "zooctl bank repair" in r.err and "Traceback" not in r.err, r.err
    r = run_inprocess(capsys, "--store", str(root), "bank", "add", str(write_tiny_glb(tmp_path / "d.glb")))
    assert r.code != 0 and "zooctl bank repair" in r.err
    after = {k: v for k, v in hashes(root).items() if not k.endswith("index.json")}
    assert after == before  # nothing deleted, nothing half-added
    r = run_inprocess(capsys, "--store", str(root), "bank", "repair", "--json")
    assert r.code == 0, r.err
    assert r.json()["indexed"] == ["a", "b", "c"] and r.json()["written"]
    assert Bank(root).names() == ["a", "b", "c"]
    validate(json.loads(bank.index_path.read_text()), "bank_index")
    assert run_inprocess(capsys, "--store", str(root), "bank", "show", "b", "--json").json()["name"] == "b"


def test_repair_skips_damaged_files_keeps_them_and_rewrites_lost_cards(tmp_path, capsys):
    root = tmp_path / "store"
    bank = tiny_bank(root)
    data = bank.asset_path("b").read_bytes()
    bank.asset_path("b").write_bytes(data[: len(data) // 3])  # truncated asset file
    (bank.assets_dir / "junk.h5").write_bytes(b"not hdf5")
    bank.card_path("c").unlink()
    bank.index_path.unlink()
    r = run_inprocess(capsys, "--store", str(root), "bank", "repair")
    assert r.code == 0, r.err
    assert "skipped b" in r.err and "skipped junk" in r.err
    assert "c: card rewritten" in r.out
    assert bank.names() == ["a", "c"]
    assert bank.asset_path("b").read_bytes() == data[: len(data) // 3]  # left where it was
    assert bank.card("c")["joint_names"]
    r = run_inprocess(capsys, "--store", str(root), "bank", "repair", "--json")
    assert r.json()["written"] is False  # a second repair finds nothing to change


def test_clean_never_deletes_an_asset_file(tmp_path, capsys):
    root = tmp_path / "store"
    bank = tiny_bank(root)
    index = json.loads(bank.index_path.read_text())
    del index["assets"]["c"]  # as a writer killed between publishing c and the index
    bank.index_path.write_text(json.dumps(index))
    (bank.assets_dir / "gone.json").write_text("{}")  # the card of an asset that is gone
    dead_tmp = bank.assets_dir / ".a.h5.999999999.x.tmp"  # a dead writer's temporary
    dead_tmp.write_bytes(b"x")
    r = run_inprocess(capsys, "--store", str(root), "bank", "clean")
    assert r.code == 0, r.err
    assert "kept 1 asset files" in r.err and "(c)" in r.err and "zooctl bank repair" in r.err
    assert bank.asset_path("c").is_file() and bank.card_path("c").is_file()
    assert not (bank.assets_dir / "gone.json").exists() and not dead_tmp.exists()
    assert bank.repair()["indexed"] == ["a", "b", "c"]


def test_video_index_lost_or_damaged_then_repaired(tmp_path, capsys):
    root = tmp_path / "store"
    vs = VideoStore(root)
    for i, n in enumerate(("v1", "v2")):
        vs.add(synthetic_video(n, seed=i))
    want = vs.list()
    validate(json.loads(vs.index_path.read_text()), "video_index")
    (vs.dir / "v2.cache").mkdir()
    for how in (None, "[]", "{}", '{"schema_version": 1, "videos": {"v1": {"name": "v1"}}}'):
        if how is None:
            vs.index_path.unlink()
        else:
            vs.index_path.write_text(how)
        for args in (["video", "list"], ["video", "show", "v1"], ["video", "clean"], ["video", "rm", "v1"]):
            r = run_inprocess(capsys, "--store", str(root), *args)
            assert r.code != 0 and "zooctl video repair" in r.err and "Traceback" not in r.err, (how, r.err)
        assert vs.path("v1").is_file() and vs.path("v2").is_file() and (vs.dir / "v2.cache").is_dir()
        with pytest.raises(StoreError) as err:
            vs.add(synthetic_video("v3"))
        assert "zooctl video repair" in err.value.hint
        r = run_inprocess(capsys, "--store", str(root), "video", "repair")
        assert r.code == 0 and "2 videos indexed" in r.out, r.err
        assert vs.list() == want
    vs.path("v1").write_bytes(vs.path("v1").read_bytes()[:5000])
    report = vs.repair()
    assert report["indexed"] == ["v2"] and "v1" in report["skipped"] and report["dropped"] == ["v1"]
    assert vs.path("v1").is_file()
    r = run_inprocess(capsys, "--store", str(root), "video", "clean")
    assert r.code == 0 and "(v1)" in r.err and vs.path("v1").is_file()


def test_a_store_with_no_files_and_no_index_is_empty(tmp_path):
    assert Bank(tmp_path).names() == [] and VideoStore(tmp_path).names() == []
    assert Bank(tmp_path).cleanup()["unindexed"] == []


def test_a_waiting_writer_says_who_holds_the_lock_and_gives_up(tmp_path):
    root = tmp_path / "store"
    tiny_bank(root, names=("a",))
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, time; from pathlib import Path; from zooctl.store.fs import store_lock\n"
            "with store_lock(Path(sys.argv[1])):\n    print('HELD', flush=True); time.sleep(60)",
            str(root),
        ],
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    try:
        assert holder.stdout.readline().strip() == "HELD"
        info = json.loads((root / ".lock").read_text())
        validate(info, "store_lock")
        assert info["pid"] == holder.pid
        env = {**os.environ, "PYTHONPATH": str(REPO), "ZOOCTL_STORE": str(root)}
        r = subprocess.run(
            [sys.executable, "-m", "zooctl", "--wait", "0.5", "bank", "rm", "a"],
            capture_output=True,
            text=True,
            env=env,
            timeout=60,
        )
        assert r.returncode == 1 and "Traceback" not in r.stderr
        assert f"waiting for the store lock, held by pid {holder.pid}" in r.stderr
        assert "gave up after 0.5 s" in r.stderr and "--wait" in r.stderr
        env["ZOOCTL_LOCK_TIMEOUT"] = "0.2"  # the environment variable still works
        r = subprocess.run(
            [sys.executable, "-m", "zooctl", "bank", "rm", "a"],
            capture_output=True,
            text=True,
            env=env,
            timeout=60,
        )
        assert r.returncode == 1 and "gave up after 0.2 s" in r.stderr
    finally:
        holder.kill()
        holder.wait()
    assert Bank(root).names() == ["a"]


def test_repair_keeps_retrieval_views_that_belong_to_the_asset(tmp_path, monkeypatch):
    from zooctl.pipelines.bank_import import add_files

    monkeypatch.setenv("ZOOCTL_EMBEDDERS", "silhouette")
    root = tmp_path / "store"
    bank = Bank(root)
    glbs = [write_tiny_glb(tmp_path / f"{n}.glb") for n in ("a", "b")]
    assert all(r.error is None for r in add_files(bank, glbs, views=True))
    want = {s["name"]: s["views"] for s in bank.list()}
    bank.index_path.unlink()
    (root / "bank" / "views" / "b.h5").write_bytes(b"damaged")
    report = bank.repair()
    assert report["indexed"] == ["a", "b"]
    assert any("b: its retrieval views are gone" in n for n in report["fixed"])
    got = {s["name"]: s.get("views") for s in bank.list()}
    # The embedders' identities live only in the index: a rebuilt entry has none, which search
    # reads as a bank indexed before they were recorded.
    assert got["a"] == {k: v for k, v in want["a"].items() if k != "identities"}
    assert got["b"] is None  # `bank reindex --missing` renders b again
    validate(json.loads(bank.index_path.read_text()), "bank_index")


def test_repair_never_rewrites_an_index_of_a_newer_zooctl(tmp_path):
    bank = tiny_bank(tmp_path / "store", names=("a",))
    newer = '{"schema_version": 2, "assets": {}}'
    bank.index_path.write_text(newer)
    with pytest.raises(StoreError, match="schema version 2") as err:
        bank.repair()
    assert err.value.hint == "upgrade zooctl" and bank.index_path.read_text() == newer
    bank.index_path.write_text('{"schema_version": 1, "assets": [1, 2]}')
    assert bank.repair()["indexed"] == ["a"]
