"""The quick subset of the damaged-store fuzz: one seeded state of each kind of damage, each put
to the usual commands (`store_fuzz` says what passes). The full run is ``bench/fuzz_store.py``."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))  # whatever else tests/fuzz/ holds
from store_fuzz import KINDS, PERMISSIONS_APPLY, REPO, build_base, plan, run_state  # noqa: E402

SHARED = REPO.parent / "shared" / "data"
ASSETS = sorted((SHARED / "assets" / "quaternius").glob("*/*.glb"))
VIDEO = SHARED / "videos" / "cows"
SEED = 18
STATES = [next((s, k) for s, k in plan(len(KINDS) * 3, SEED) if k == kind) for kind in KINDS]

pytestmark = pytest.mark.skipif(
    len(ASSETS) < 4 or not VIDEO.is_dir(),
    reason=f"shared test assets and videos not found under {SHARED} (a fresh clone has no ../shared/data)",
)


@pytest.fixture(scope="module", autouse=True)
def silhouette_only():
    """`build_base` sets ZOOCTL_EMBEDDERS for the rest of the process (the bench wants that); here it
    ends with this module, or later tests in the same worker lose the default embedders."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("ZOOCTL_EMBEDDERS", "silhouette")
        yield


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    root = tmp_path_factory.mktemp("fuzzbase") / "store"
    return root, build_base(root, ASSETS[:3], VIDEO)


@pytest.mark.parametrize("seed,kind", STATES, ids=[k for _, k in STATES])
def test_damaged_store_state(base, tmp_path, seed, kind):
    if kind in ("unreadable", "readonly") and not PERMISSIONS_APPLY:
        pytest.skip("running as root without setpriv: file permissions do not apply")
    root, info = base
    rec = run_state(root, info, tmp_path, seed, kind, ASSETS[3])
    assert rec["damage"] and rec["outcomes"], rec
    assert not rec["problems"], rec
