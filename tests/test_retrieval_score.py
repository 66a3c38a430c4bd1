"""Scoring and aggregation (CASA supplement H and alternatives), fusion, and the two-stage search."""

from __future__ import annotations

import numpy as np
import pytest

from zooctl.errors import UsageError
from zooctl.retrieval.score import aggregate, best_views, distances, fuse


def test_distances_pad_with_inf():
    q = np.array([[1.0, 0.0], [0.0, 1.0]])
    views = np.array([[[1.0, 0.0], [0.0, 1.0]], [[-1.0, 0.0], [0.0, 0.0]]])
    d = distances(q, views, np.array([2, 1]))
    assert d.shape == (2, 2, 2)
    np.testing.assert_allclose(d[0], [[0, 1], [1, 0]], atol=1e-6)
    np.testing.assert_allclose(d[1, :, 0], [2, 1], atol=1e-6)
    assert np.isinf(d[1, :, 1]).all()


def test_aggregations_differ_as_documented():
    # asset 0: every frame has one perfect view; asset 1: one perfect pair, otherwise poor;
    # asset 2: uniformly mediocre.
    d = np.array(
        [
            [[0.0, 0.9, 0.9], [0.9, 0.0, 0.9], [0.9, 0.9, 0.0]],
            [[0.0, 0.9, 0.9], [0.8, 0.8, 0.8], [0.8, 0.8, 0.8]],
            [[0.3, 0.3, 0.3], [0.3, 0.3, 0.3], [0.3, 0.3, 0.3]],
        ]
    )
    assert np.argmin(aggregate(d, "nearest")) == 0
    np.testing.assert_allclose(aggregate(d, "nearest"), [0.0, (0 + 0.8 + 0.8) / 3, 0.3])
    np.testing.assert_allclose(aggregate(d, "min"), [0, 0, 0.3])
    np.testing.assert_allclose(aggregate(d, "kmin", k=3), [0, (0 + 0.8 + 0.8) / 3, 0.3])
    assert np.argmin(aggregate(d, "mean")) == 2  # the mean prefers the mediocre asset
    with pytest.raises(UsageError):
        aggregate(d, "median")


def test_aggregations_ignore_padding():
    d = np.full((1, 2, 3), np.inf)
    d[0, :, :2] = [[0.2, 0.4], [0.6, 0.1]]
    np.testing.assert_allclose(aggregate(d, "mean"), [0.325])
    np.testing.assert_allclose(aggregate(d, "kmin", k=10), [0.325])
    np.testing.assert_allclose(aggregate(d, "nearest"), [0.15])
    overall, per_frame = best_views(d)
    assert overall[0] == 1 and list(per_frame[0]) == [0, 1]


def test_fusion():
    a = {"x": np.array([0.1, 0.2, 0.3, 0.4]), "y": np.array([10.0, 9.0, 30.0, 40.0])}
    z = fuse(a, "zsum")
    assert np.argmin(z) in (0, 1) and np.argmax(z) == 3
    s = fuse(a, "sum")
    assert np.argmin(s) == 1  # raw sums are dominated by the larger scale
    r = fuse(a, "rank")
    np.testing.assert_allclose(r, [1, 1, 4, 6])
    np.testing.assert_allclose(fuse(a, "zsum", weights={"x": 1.0, "y": 0.0}), fuse({"x": a["x"]}, "zsum"))
    with pytest.raises(UsageError):
        fuse(a, "max")


def test_two_stage_search_finds_the_planted_asset(store):
    from zooctl.retrieval.benchmark import synthetic_bank
    from zooctl.retrieval.search import score_bank
    from zooctl.store import views_h5
    from zooctl.store.bank import Bank

    synthetic_bank(store, 300, {"toy": 32}, n_views=6, seed=0)
    pack = views_h5.read_pack(store, "toy")
    target = 123
    q = np.asarray(pack.emb[target, :4], np.float32) + 0.05 * np.random.default_rng(1).normal(size=(4, 32))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    bank = Bank(store)
    exact = score_bank(bank, {"toy": q}, shortlist=10_000)
    fast = score_bank(bank, {"toy": q}, shortlist=20)
    assert exact.candidates == 300 and fast.candidates == 20
    assert exact.matches[0].name == fast.matches[0].name == pack.names[target]
    np.testing.assert_allclose(fast.matches[0].distances["toy"], exact.matches[0].distances["toy"], rtol=1e-4)
    excluded = score_bank(bank, {"toy": q}, exclude={pack.names[target]})
    assert pack.names[target] not in [m.name for m in excluded.matches]


def test_leave_one_out_benchmark_on_procedural_animals(tmp_path):
    """The evaluation machinery end to end on three small procedural animals (silhouette only)."""
    from zooctl.procedural import build_animal
    from zooctl.retrieval.benchmark import COLUMNS, loo_benchmark, summary_rows
    from zooctl.retrieval.evaluate import body_plan

    assets = [
        build_animal("fish", name="FishA"),
        build_animal("fish", name="FishB", seed=1),
        build_animal("spider", name="Spid"),
    ]
    assert [body_plan(a) for a in assets] == ["fish", "fish", "spider"]
    report = loo_benchmark(assets, tmp_path / "s", ["silhouette"], n_views=6, size=48, frames=3)
    assert report["assets"] == 3 and len(report["results"]) == 4  # one per aggregation
    r = report["results"][0]
    assert r["queries"] == 3 and r["skeleton_queries"] == 2  # the fishes are skeleton twins
    # the spider has no other spider: it can never be right, and "answerable" leaves it out
    spider = next(row for row in r["rows"] if row["query"] == "Spid")
    assert not spider["answerable"] and not spider["top1_plan"]
    assert r["top1_plan"] <= 2 / 3
    fish_rows = [row for row in r["rows"] if row["plan"] == "fish"]
    assert r["top1_plan_answerable"] == sum(row["top1_plan"] for row in fish_rows) / 2
    assert all(len(row) == len(COLUMNS) for row in summary_rows(report))
    # queries: only the named assets are queried; the others are bank content (answerable now
    # counts the whole bank: a second spider makes the spider query answerable)
    more = [*assets, build_animal("spider", name="Spid2", seed=1)]
    sub = loo_benchmark(more, tmp_path / "q", ["silhouette"], n_views=6, size=48, frames=3, queries=["Spid"])
    assert sub["assets"] == 4 and sub["queries"] == 1
    (row,) = sub["results"][0]["rows"]
    assert row["query"] == "Spid" and row["answerable"]


def test_fuse_terms_add_up_to_the_fused_score():
    from zooctl.retrieval.score import fuse, fuse_terms

    rng = np.random.default_rng(0)
    scores = {"a": rng.random(6), "b": 3 * rng.random(6)}
    for how in ("zsum", "sum", "rank"):
        terms = fuse_terms(scores, how, {"a": 2.0})
        np.testing.assert_allclose(terms["a"] + terms["b"], fuse(scores, how, {"a": 2.0}))
    z = fuse_terms(scores, "zsum")
    assert abs(z["b"].mean()) < 1e-9 and z["b"].std() == pytest.approx(1.0)


def test_missing_views_notes_name_the_assets_left_out_once(monkeypatch):
    """An asset without any views is one note naming it (not one per embedder); an asset that lacks
    only one embedder's views is that embedder's note."""
    from zooctl.retrieval.search import missing_views_notes

    monkeypatch.delenv("ZOOCTL_EMBEDDERS", raising=False)
    notes = missing_views_notes({"effnet": ["demo-fit", "b"], "silhouette": ["demo-fit"]})
    assert len(notes) == 2
    assert "1 asset without retrieval views" in notes[0] and "demo-fit" in notes[0]
    assert "reindex --missing" in notes[0]
    assert notes[1].startswith("effnet: 1 asset has no views") and "--embedder effnet" in notes[1]
    many = missing_views_notes(
        {"effnet": [f"a{i}" for i in range(7)], "silhouette": [f"a{i}" for i in range(7)]}
    )
    assert many == [
        "7 assets without retrieval views left out of the search: a0, a1, a2, a3, a4 and 2 more "
        "(`zooctl bank reindex --missing` renders them)"
    ]
    assert missing_views_notes({"effnet": [], "silhouette": []}) == []
    # another embedder than the defaults: the command says which, as `reindex` would embed the defaults
    only = missing_views_notes({"procnet": ["x"]})[0]
    assert (
        only.startswith("1 asset without procnet views") and "reindex --missing --embedder procnet`" in only
    )
