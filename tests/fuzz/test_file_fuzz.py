"""Import fuzz, quick subset (the full run: bench/fuzz_files.py): mutated glTF/GLB/USD files
through `bank add` end in success or one clear error line, within 60 s and 2 GB, and leave the
store's other files byte-identical."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # file_mutants, however pytest imports us
import file_mutants as fm  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from zooctl.store.bank import Bank  # noqa: E402

QUICK_LIBRARY = 150
QUICK_CLI = 6


def _report(outcomes) -> str:
    bad = [o for o in outcomes if not o.passed]
    return "\n".join(f"{o.via} {o.case.name}: {o.status}: {o.detail[:300]}" for o in bad[:20])


def test_mutated_files_import_cleanly(tmp_path):
    cases = fm.mutants(tmp_path / "files", QUICK_LIBRARY, seed=18)
    kinds = {c.kind for c in cases}
    assert len(kinds) >= 20 and {"key_times", "glb_truncate", "uri_buffer"} <= kinds, kinds
    assert kinds & set(fm.SIZE_KINDS), kinds  # FIFOs, devices, sparse files, declared sizes
    store = tmp_path / "store"
    base = fm.make_store(store)
    lib = fm.run_library(cases, store)
    cli = fm.run_cli(cases[:: len(cases) // QUICK_CLI][:QUICK_CLI], store)
    outcomes = lib + cli
    assert all(o.passed for o in outcomes), _report(outcomes)
    counts = fm.summarize(lib)
    assert counts.get("error", 0) > 0 and counts.get("ok", 0) > 0, counts  # both paths exercised
    # every escaping URI was refused
    assert all(o.status == "error" for o in lib if o.case.must_fail)
    # the stored asset is still there and whole
    assert Bank.open(store).list()[0]["name"] == base
    assert Bank.open(store).get(base).num_vertices == 4


def test_special_and_huge_files_are_refused_unread(tmp_path):
    """Every class of file that would block or bomb: each a clear error, at once, in little memory."""
    rng = np.random.default_rng(0)
    cases = [
        fm.size_case(rng, tmp_path / "files" / f"{kind}-{how}", i, kind, how)
        for i, (kind, how) in enumerate(
            [(k, h) for k in fm.SIZE_KINDS if k.startswith("special") for h in fm.SPECIALS]
            + [(k, None) for k in fm.SIZE_KINDS if not k.startswith("special")]
        )
    ]
    store = tmp_path / "store"
    fm.make_store(store)
    outcomes = fm.run_library(cases, store) + fm.run_cli(cases[:2], store)
    assert all(o.status == "error" for o in outcomes), _report(outcomes)  # a hang is "hang"
    assert max(o.peak_kb for o in outcomes) < fm.MAX_RSS_KB


def test_the_fuzz_catches_what_it_looks_for(tmp_path):
    """The judge is not a rubber stamp: a traceback, a breach, a stored change and a big peak fail."""
    case = fm.Case("x", "count", tmp_path / "x.glb")
    assert (
        fm._judge(case, "library", {"status": "internal", "message": "IndexError: boom"}).status == "internal"
    )
    assert fm._judge(case, "library", {"status": "error", "message": "two\nlines"}).status == "unclear"
    secret = fm.Case("y", "uri_buffer", tmp_path / "y.gltf", must_fail=True)
    assert fm._judge(secret, "library", {"status": "ok"}).status == "breach"
    changed = {"status": "error", "message": "bad", "changed": ["bank/index.json"]}
    assert fm._judge(case, "library", changed).status == "store_changed"
    big = {"status": "ok", "peak_kb": fm.MAX_RSS_KB + 1}
    assert fm._judge(case, "library", big).status == "memory"


def test_a_value_past_float32_is_one_clear_line_through_the_cli(tmp_path):
    """The full run's one failure (seed 18, case 420, `nan` on the tiny rig): a scale past float32's
    range printed numpy's overflow warning before the clear error."""
    if not all((fm.SHARED_ASSETS / rel).is_file() for rel in fm.SMALL_SHARED):
        pytest.skip(f"the shared assets the case was made from are not at {fm.SHARED_ASSETS}")
    cases = fm.mutants(tmp_path / "files", 421, seed=18)
    case = next(c for c in cases if c.name == "0420_nan_tiny")
    store = tmp_path / "store"
    fm.make_store(store)
    outcomes = fm.run_cli([case], store)
    assert all(o.passed for o in outcomes), _report(outcomes)
