from __future__ import annotations

import os
from pathlib import Path

import pytest

# One thread per test process: CI has 2 cores and runs two pytest workers; on this machine one
# torch thread was also faster than two for our small kernels.
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
# Rich fixes a console's width when it is built if COLUMNS is set then (CI may set 80); set ours
# before any test module imports the CLI, so assertions never meet a line wrapped mid-phrase.
os.environ["COLUMNS"] = "200"
try:
    import torch

    torch.set_num_threads(1)
except ImportError:  # pragma: no cover - torch is a hard dependency; keep conftest importable
    pass

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"
ASSETS_DIR = SHARED / "assets" / "quaternius"
VIDEOS_DIR = SHARED / "videos"


def shared_assets() -> list[Path]:
    return sorted(ASSETS_DIR.glob("*/*.glb")) if ASSETS_DIR.is_dir() else []


needs_shared_assets = pytest.mark.skipif(
    not shared_assets(),
    reason=f"shared test assets not found at {ASSETS_DIR} (a fresh clone has no ../shared/data)",
)
needs_shared_videos = pytest.mark.skipif(
    not VIDEOS_DIR.is_dir(),
    reason=f"shared test videos not found at {VIDEOS_DIR} (a fresh clone has no ../shared/data)",
)


@pytest.fixture
def store(tmp_path, monkeypatch) -> Path:
    """An empty store root; ZOOCTL_STORE points at it for the CLI."""
    root = tmp_path / "store"
    monkeypatch.setenv("ZOOCTL_STORE", str(root))
    return root


@pytest.fixture
def one_thread():
    """One torch thread for tests of optimisation loops of many small ops: two threads thrash
    OpenMP on a busy 2-core machine. Use with ``pytestmark = pytest.mark.usefixtures("one_thread")``."""
    import torch

    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


@pytest.fixture(autouse=True)
def _quiet_env(monkeypatch):
    from zooctl.paths import use_store

    use_store(None)  # an earlier in-process CLI call's --store does not carry into this test
    monkeypatch.delenv("ZOOCTL_DEBUG", raising=False)
    monkeypatch.setenv("COLUMNS", "200")
    # `bank add` renders and embeds retrieval views (~2 s of CPU per asset); tests that need
    # views turn them on themselves.
    monkeypatch.setenv("ZOOCTL_VIEWS", "0")
