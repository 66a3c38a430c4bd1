"""The store's lock file is never written through: a ``.lock`` that is a symlink (to a file outside
the store, existing or not) or a FIFO makes the store refuse writes with one clear line, and the
link's target is left as it was (not emptied, overwritten or created)."""

from __future__ import annotations

import os

import pytest
from cli_helpers import run_inprocess

from zooctl.errors import StoreError
from zooctl.store.fs import store_lock


@pytest.mark.parametrize("target_exists", [True, False])
def test_a_symlinked_lock_is_refused_and_its_target_untouched(tmp_path, target_exists):
    root = tmp_path / "store"
    root.mkdir()
    target = tmp_path / "outside.txt"
    if target_exists:
        target.write_text("precious")
    (root / ".lock").symlink_to(target)
    with pytest.raises(StoreError, match="symbolic link"):
        with store_lock(root):
            pass
    if target_exists:
        assert target.read_text() == "precious"
    else:
        assert not target.exists()


def test_a_fifo_lock_is_refused_without_hanging(tmp_path):
    root = tmp_path / "store"
    root.mkdir()
    os.mkfifo(root / ".lock")
    with pytest.raises(StoreError, match="not a regular file"):
        with store_lock(root):
            pass


def test_the_cli_says_so_in_one_line(store, tmp_path, capsys):
    store.mkdir(parents=True)
    target = tmp_path / "victim"
    target.write_text("keep me")
    (store / ".lock").symlink_to(target)
    r = run_inprocess(capsys, "bank", "seed")
    assert r.code != 0 and "symbolic link" in r.err and "Traceback" not in r.err
    assert target.read_text() == "keep me"
