"""A batch worker's scratch folder: removed by the next task once its worker is gone, never while
it lives."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

from zooctl.pipelines.worker_scratch import PREFIX, claim, release, scratch_path, sweep_orphans

REPO = Path(__file__).resolve().parents[1]


def claimed_by_a_process_that_dies(root: Path, how: str) -> Path:
    """A scratch folder claimed by another process, which then dies without removing it."""
    code = (
        "import os, signal, sys; from pathlib import Path;"
        "from zooctl.pipelines.worker_scratch import claim, scratch_path;"
        f"p = scratch_path('dead', Path({str(root)!r})); claim(p); (p / 'frames.npz').write_bytes(b'x' * 1000);"
        "print(p, flush=True);" + ("os.kill(os.getpid(), signal.SIGKILL)" if how == "kill" else "os._exit(0)")
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=60)
    folder = Path(r.stdout.strip())
    assert folder.is_dir() and (folder / "frames.npz").is_file(), r.stderr
    return folder


def test_a_folder_whose_worker_died_is_removed_and_a_live_one_kept(tmp_path):
    killed = claimed_by_a_process_that_dies(tmp_path, "kill")
    exited = claimed_by_a_process_that_dies(tmp_path, "exit")
    live = scratch_path("live", tmp_path)
    fd = claim(live)
    other = tmp_path / "zooctl-other"
    other.mkdir()
    try:
        assert sorted(sweep_orphans(tmp_path)) == sorted([killed, exited])
        assert not killed.exists() and not exited.exists()
        assert live.is_dir() and other.is_dir()  # a live worker's folder, and not ours to sweep
        assert sweep_orphans(tmp_path) == []
    finally:
        release(fd)
    assert sweep_orphans(tmp_path) == [live]  # its process let go without removing it


def test_a_folder_without_an_owner_is_left_an_hour_and_links_are_not_followed(tmp_path):
    young = tmp_path / f"{PREFIX}young-0"
    young.mkdir()
    target = tmp_path / "elsewhere"
    target.mkdir()
    (target / "keep").write_text("x")
    (tmp_path / f"{PREFIX}link-0").symlink_to(target)
    assert sweep_orphans(tmp_path) == []
    assert sweep_orphans(tmp_path, now=time.time() + 2 * 3600) == [young]
    assert (target / "keep").is_file() and (tmp_path / f"{PREFIX}link-0").is_symlink()


def test_the_owner_file_appears_locked(tmp_path):
    """A sweep never sees a folder's owner file before its lock is taken (it is locked under
    another name, then renamed), so it cannot remove a worker's folder as it starts."""
    folder = scratch_path("x", tmp_path)
    fd = claim(folder)
    try:
        assert sorted(p.name for p in folder.iterdir()) == [".owner"]
        import fcntl

        probe = os.open(folder / ".owner", os.O_RDONLY)
        try:
            try:
                fcntl.flock(probe, fcntl.LOCK_EX | fcntl.LOCK_NB)
                locked = False
            except BlockingIOError:
                locked = True
        finally:
            os.close(probe)
        assert locked
    finally:
        release(fd)
