"""A full disk (``ulimit -f``: writes fail with EFBIG) and a read-only store: one clear error,
nothing half-committed, no temporaries left, and reads (`bank search` included) still work."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import REPO, Result
from gltf_builder import write_tiny_glb
from PIL import Image
from video_helpers import moving_object_video

from zooctl.store.bank import Bank
from zooctl.store.videos import VideoStore

# Root ignores file permissions; without these capabilities it honours them like any user.
NO_OVERRIDE = (
    ["setpriv", "--bounding-set", "-dac_override,-dac_read_search"]
    if os.geteuid() == 0 and shutil.which("setpriv")
    else []
)
needs_permissions = pytest.mark.skipif(
    os.geteuid() == 0 and not NO_OVERRIDE, reason="running as root without setpriv: permissions do not apply"
)


def cli(store: Path, *args: str, ulimit_kb: int | None = None, readonly: bool = False, env=None) -> Result:
    cmd = [sys.executable, "-m", "zooctl", "--store", str(store), *args]
    if ulimit_kb is not None:  # a full disk, in effect: writes past the size fail with EFBIG
        cmd = ["bash", "-c", f'ulimit -f {ulimit_kb}; exec "$@"', "bash", *cmd]
    if readonly:
        cmd = NO_OVERRIDE + cmd
    e = {**os.environ, "PYTHONPATH": str(REPO), "NO_COLOR": "1", "COLUMNS": "200", **(env or {})}
    p = subprocess.run(cmd, capture_output=True, text=True, env=e, cwd=REPO, timeout=300)
    return Result(p.returncode, p.stdout, p.stderr)


def snapshot(root: Path) -> dict[str, bytes]:
    """Every stored file (the lock file, which names its last holder, aside)."""
    return {
        str(p.relative_to(root)): p.read_bytes()
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.name != ".lock"
    }


def one_clear_line(r: Result, text: str) -> None:
    assert r.code != 0 and "Traceback" not in r.err and "internal failure" not in r.err, r.err
    lines = r.err.strip().splitlines()
    assert lines[0].startswith("error:") and text in lines[0], r.err
    assert len(lines) <= 2  # the error and its hint


@pytest.fixture(scope="module")
def davis_folder(tmp_path_factory) -> Path:
    frames, masks = moving_object_video(t=6, h=96, w=128)
    root = tmp_path_factory.mktemp("syn")
    for sub in ("JPEGImages", "Annotations"):
        (root / sub).mkdir()
    for i, (f, m) in enumerate(zip(frames, masks)):
        Image.fromarray(f).save(root / "JPEGImages" / f"{i:05d}.png")
        Image.fromarray(m.astype(np.uint8) * 255).save(root / "Annotations" / f"{i:05d}.png")
    return root


SILHOUETTE = {"ZOOCTL_EMBEDDERS": "silhouette"}


def test_disk_full_during_bank_add_changes_nothing(tmp_path):
    store, glb = tmp_path / "store", write_tiny_glb(tmp_path / "t.glb")
    assert cli(store, "bank", "add", str(glb), "--name", "keep", "--no-views").code == 0
    before = snapshot(store)
    r = cli(store, "bank", "add", str(glb), "--name", "new", "--no-views", ulimit_kb=4)
    one_clear_line(r, "no space left on device / file too large")
    assert snapshot(store) == before  # no temporaries, no half-added asset
    assert Bank(store).names() == ["keep"]


def test_disk_full_while_writing_views_removes_the_new_asset(tmp_path):
    """The asset fits, its views do not: the add is undone (no asset in the index without views)."""
    store, glb = tmp_path / "store", write_tiny_glb(tmp_path / "t.glb")
    assert cli(store, "bank", "add", str(glb), "--name", "keep", "--no-views").code == 0
    before = snapshot(store)
    r = cli(store, "bank", "add", str(glb), "--name", "new", "--views", ulimit_kb=30, env=SILHOUETTE)
    one_clear_line(r, "new was not added: its retrieval views failed: no space left")
    assert "added new" not in r.out
    assert snapshot(store) == before and Bank(store).names() == ["keep"]


def test_disk_full_during_video_add_changes_nothing(tmp_path, davis_folder):
    store = tmp_path / "store"
    r = cli(store, "video", "add", str(davis_folder), "--name", "v", "-q", ulimit_kb=20)
    one_clear_line(r, "no space left on device / file too large")
    assert VideoStore(store).names() == []
    assert [p.name for p in (store / "videos").iterdir()] == []  # the temporary is gone


@needs_permissions
def test_read_only_store_refuses_writes_clearly_and_searches_without_writing(tmp_path, davis_folder):
    store, glb = tmp_path / "store", write_tiny_glb(tmp_path / "t.glb")
    assert cli(store, "bank", "add", str(glb), "--name", "a", "--views", env=SILHOUETTE).code == 0
    assert cli(store, "video", "add", str(davis_folder), "--name", "v", "-q").code == 0
    before = snapshot(store)
    subprocess.run(["chmod", "-R", "a-w", str(store)], check=True)
    try:
        for args in (
            ["bank", "add", str(glb), "--name", "b", "--no-views"],
            ["bank", "rm", "a"],
            ["bank", "clean"],
            ["bank", "migrate"],
            ["bank", "repair"],
            ["video", "rm", "v"],
            ["video", "clean"],
            ["video", "repair"],
            ["video", "add", str(davis_folder), "--name", "w", "-q"],
        ):
            one_clear_line(cli(store, *args, readonly=True), "the store is read-only")
        r = cli(store, "bank", "list", "--json", readonly=True)
        assert r.code == 0 and [a["name"] for a in r.json()] == ["a"]
        r = cli(store, "bank", "search", "v", "--embedder", "silhouette", "--json", readonly=True)
        assert r.code == 0, r.err
        assert [m["name"] for m in r.json()["matches"]] == ["a"]
    finally:
        subprocess.run(["chmod", "-R", "u+w", str(store)], check=True)
    assert snapshot(store) == before
