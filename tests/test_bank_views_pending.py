"""A `bank add` killed after its asset is indexed but before its retrieval views are stored: `bank
clean` and `bank list` say so, `bank repair` renders the views, and search then finds the asset.
An asset added with --no-views is not such a case."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import jsonschema
import pytest
from cli_helpers import REPO, run_inprocess
from gltf_builder import write_tiny_glb
from video_helpers import moving_object_video, write_png_davis

from zooctl.store.bank import Bank

EMBEDDERS = {"ZOOCTL_EMBEDDERS": "silhouette"}


def kill_once_indexed(store: Path, glb: Path, name: str) -> None:
    """Run `bank add` (views on) and SIGKILL it as soon as the bank index names the asset."""
    env = {**os.environ, "PYTHONPATH": str(REPO), "ZOOCTL_STORE": str(store), **EMBEDDERS}
    p = subprocess.Popen(
        [sys.executable, "-c", SLOW_ADD, str(glb), name],
        env=env,
        cwd=REPO,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    index = store / "bank" / "index.json"
    deadline = time.monotonic() + 120
    try:
        while time.monotonic() < deadline and p.poll() is None:
            try:
                if name in json.loads(index.read_bytes())["assets"]:
                    break
            except (OSError, ValueError, KeyError):
                pass
            time.sleep(0.005)
        assert p.poll() is None, p.stderr.read().decode()
        p.send_signal(signal.SIGKILL)
    finally:
        p.wait()


# `bank add` as the CLI runs it, with the view renderer slowed by a sleep (a test-side wrapper, not
# a hook in zooctl), so the kill lands between the indexed asset and its stored views.
SLOW_ADD = """
import sys, time
import zooctl.retrieval.index as index
real = index.compute_views
def slow(*a, **k):
    time.sleep(30)
    return real(*a, **k)
index.compute_views = slow
from zooctl.cli.main import run
sys.exit(run(["bank", "add", sys.argv[1], "--name", sys.argv[2], "--views"]))
"""


@pytest.fixture
def query(tmp_path) -> Path:
    return write_png_davis(tmp_path / "q", *moving_object_video(t=4, h=64, w=64))


def test_a_killed_add_is_reported_and_repair_renders_its_views(tmp_path, capsys, monkeypatch, query):
    monkeypatch.setenv("ZOOCTL_EMBEDDERS", "silhouette")
    store, glb = tmp_path / "store", write_tiny_glb(tmp_path / "t.glb")
    bank = Bank(store)
    assert (
        run_inprocess(
            capsys, "--store", str(store), "bank", "add", str(glb), "--name", "done", "--views"
        ).code
        == 0
    )
    r = run_inprocess(capsys, "--store", str(store), "bank", "add", str(glb), "--name", "plain", "--no-views")
    assert r.code == 0, r.err
    kill_once_indexed(store, glb, "killed")

    assert bank.names() == ["done", "killed", "plain"]
    assert "views" not in bank.summary("killed") and bank.views_pending() == ["killed"]
    schema = json.loads((REPO / "schemas" / "bank_index.schema.json").read_text())
    jsonschema.validate(json.loads((store / "bank" / "index.json").read_text()), schema)

    r = run_inprocess(capsys, "--store", str(store), "bank", "clean")
    assert r.code == 0 and "1 asset without the retrieval views" in r.err and "(killed)" in r.err, r.err
    assert "zooctl bank repair" in r.err and "plain" not in r.err  # --no-views was asked for
    r = run_inprocess(capsys, "--store", str(store), "bank", "clean", "--json")
    assert r.json()["views_pending"] == ["killed"]
    r = run_inprocess(capsys, "--store", str(store), "bank", "list")
    assert r.code == 0 and "(killed)" in r.err and "zooctl bank repair" in r.err, r.err
    r = run_inprocess(capsys, "--store", str(store), "bank", "search", str(query), "--json")
    assert r.code == 0, r.err
    assert [m["name"] for m in r.json()["matches"]] == ["done"]

    r = run_inprocess(capsys, "--store", str(store), "bank", "repair")
    assert r.code == 0 and "rendered the retrieval views" in r.out and "killed" in r.out, (r.out, r.err)
    entry = bank.summary("killed")
    assert entry["views"]["count"] > 0 and "views_pending" not in entry
    assert "views" not in bank.summary("plain")  # an asset added without views stays so
    r = run_inprocess(capsys, "--store", str(store), "bank", "clean")
    assert r.code == 0 and "retrieval views" not in r.err, r.err
    r = run_inprocess(capsys, "--store", str(store), "bank", "search", str(query), "--json")
    assert r.code == 0, r.err
    assert sorted(m["name"] for m in r.json()["matches"]) == ["done", "killed"]
    r = run_inprocess(capsys, "--store", str(store), "bank", "repair", "--json")
    assert r.json()["views_rendered"] == [] and r.json()["written"] is False


def test_a_finished_add_leaves_no_pending_mark(tmp_path, monkeypatch):
    monkeypatch.setenv("ZOOCTL_EMBEDDERS", "silhouette")
    from zooctl.pipelines.bank_import import add_files

    store, glb = tmp_path / "store", write_tiny_glb(tmp_path / "t.glb")
    bank = Bank(store)
    (r,) = add_files(bank, [glb], name="a", views=True)
    assert r.error is None and "views_pending" not in r.summary
    assert "views_pending" not in bank.summary("a") and bank.views_pending() == []
