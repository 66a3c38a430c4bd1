"""Search caches: the per-embedder pack of the bank's view embeddings, and the query embeddings
cached beside a stored video. Both go stale when what they describe changes, and a damaged cache
is rebuilt, never an error."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest


@pytest.fixture
def bank_two(store):
    """A bank of two procedural animals with small silhouette views (no torch needed)."""
    from zooctl.procedural import build_animal
    from zooctl.retrieval.index import index_asset
    from zooctl.store.bank import Bank

    bank = Bank(store)
    for kind, name in (("quadruped", "Quad"), ("snake", "Noodle")):
        a = build_animal(kind, name=name)
        bank.add(a)
        index_asset(bank, a, ["silhouette"], n_views=3, size=48)
    return bank


def _query(seed: int = 0) -> dict[str, np.ndarray]:
    q = np.random.default_rng(seed).normal(size=(2, 576)).astype(np.float32)
    return {"silhouette": q / np.linalg.norm(q, axis=1, keepdims=True)}


def test_pack_is_stale_after_rm_and_a_damaged_pack_is_rebuilt(bank_two, store):
    from zooctl.retrieval.index import current_pack
    from zooctl.retrieval.search import score_bank
    from zooctl.store import views_h5

    pack, _ = current_pack(bank_two, "silhouette")
    assert pack.names == ["Noodle", "Quad"]
    before = [m.name for m in score_bank(bank_two, _query()).matches]
    bank_two.remove("Noodle")
    pack, missing = current_pack(bank_two, "silhouette")
    assert pack.names == ["Quad"] and missing == []
    d = store / "bank" / "views"
    # damage each part of the pack in turn: truncated data, deleted or emptied mean file, garbage metadata
    for damage in ("truncate", "delete", "empty", "garbage"):
        meta = views_h5.read_pack(store, "silhouette")
        files = sorted(d.glob("pack-silhouette-*.npy"))
        assert len(files) == 2 and meta is not None
        if damage == "truncate":
            emb = next(f for f in files if not f.name.endswith(".mean.npy"))
            emb.write_bytes(emb.read_bytes()[:100])
        elif damage == "delete":
            next(f for f in files if f.name.endswith(".mean.npy")).unlink()
        elif damage == "empty":  # np.load raises EOFError: the store fuzz's one failure (Aborted.)
            next(f for f in files if f.name.endswith(".mean.npy")).write_bytes(b"")
        else:
            (d / "pack-silhouette.json").write_text("{not json")
        assert views_h5.read_pack(store, "silhouette") is None
        res = score_bank(bank_two, _query())
        assert [m.name for m in res.matches] == ["Quad"]
        assert views_h5.read_pack(store, "silhouette").names == ["Quad"]  # rebuilt on disk
    assert before[0] in ("Noodle", "Quad")


@pytest.fixture
def stored_video(tmp_path):
    """A store holding one short masked video named ``seq``."""
    from video_helpers import stored_masked_video

    return stored_masked_video(tmp_path)


def test_query_embeddings_are_cached_beside_the_stored_video(stored_video):
    from zooctl.retrieval import query_cache
    from zooctl.retrieval.query import load_query
    from zooctl.retrieval.search import query_embeddings
    from zooctl.store.videos import VideoStore

    root, folder = stored_video
    videos = VideoStore(root)
    path = query_cache.cache_path(videos, "seq", 4, 64)
    q1, e1, _ = query_embeddings("seq", ["silhouette"], k=4, size=64, store_root=root)
    assert q1.images.shape == (4, 64, 64, 3) and path.exists()  # decoded, embedded, cached
    # the crops equal those of the source folder: only the sampled frames were decoded
    np.testing.assert_array_equal(q1.images, load_query(folder, k=4, size=64).images)
    q2, e2, _ = query_embeddings("seq", ["silhouette"], k=4, size=64, store_root=root)
    assert q2.images.shape == (0, 64, 64, 3) and q2.masks is not None  # served from the cache
    np.testing.assert_array_equal(q2.frames, q1.frames)
    np.testing.assert_array_equal(e2["silhouette"], e1["silhouette"])
    q3, _, _ = query_embeddings("seq", ["silhouette"], k=4, size=64, store_root=root, need_images=True)
    assert q3.images.shape == (4, 64, 64, 3)  # a gallery needs pixels
    # another sampling is another entry
    _, e4, _ = query_embeddings("seq", ["silhouette"], k=2, size=64, store_root=root)
    assert e4["silhouette"].shape == (2, 576) and query_cache.cache_path(videos, "seq", 2, 64).exists()
    # a damaged cache is a miss and is rewritten
    path.write_bytes(b"PK\x03\x04 not a zip")
    assert query_cache.read_cache(videos, "seq", 4, 64) is None
    q5, e5, _ = query_embeddings("seq", ["silhouette"], k=4, size=64, store_root=root)
    assert q5.images.shape[0] == 4
    np.testing.assert_allclose(e5["silhouette"], e1["silhouette"], atol=1e-6)
    assert query_cache.read_cache(videos, "seq", 4, 64) is not None


def test_query_cache_is_dropped_with_the_video(stored_video):
    from zooctl.retrieval import query_cache
    from zooctl.retrieval.search import query_embeddings
    from zooctl.store.videos import VideoStore
    from zooctl.video.ingest import AddOptions, add_video

    root, folder = stored_video
    videos = VideoStore(root)
    query_embeddings("seq", ["silhouette"], k=3, size=48, store_root=root)
    assert query_cache.read_cache(videos, "seq", 3, 48) is not None
    add_video(videos, folder, AddOptions(name="seq", replace=True))  # a new file: old entries are gone
    assert query_cache.read_cache(videos, "seq", 3, 48) is None
    query_embeddings("seq", ["silhouette"], k=3, size=48, store_root=root)
    assert videos.cache_dir("seq").is_dir()
    videos.remove("seq")
    assert not videos.cache_dir("seq").exists()


def test_search_of_a_cached_stored_video_does_not_import_torch(stored_video, bank_two, store):
    """The whole `bank search` path (CLI, packs, scoring) stays torch-free when nothing needs
    embedding: torch's import is most of a repeat search's time."""
    import os
    import subprocess
    import sys

    from zooctl.retrieval.search import query_embeddings

    assert stored_video[0] == store  # one store holds the video and the bank
    query_embeddings("seq", ["silhouette"], k=8, size=224, store_root=store)  # the CLI's sampling
    code = (
        "import sys; from zooctl.cli.main import run; "
        "rc = run(['bank', 'search', 'seq', '--embedder', 'silhouette', '--json']); "
        "print('TORCH' if 'torch' in sys.modules else 'NOTORCH', rc)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        env=dict(os.environ, ZOOCTL_STORE=str(store)),
        timeout=60,
    )
    assert out.stdout.strip().endswith("NOTORCH 0"), out.stdout + out.stderr


def test_a_cached_query_of_another_size_is_embedded_again(bank_two, stored_video):
    """The embedder changed size and the bank was reindexed since the video's query embeddings were
    cached: `bank search` embeds the query again (and re-caches it) instead of failing."""
    from zooctl.retrieval import query_cache
    from zooctl.retrieval.search import search_source
    from zooctl.store.videos import VideoStore

    root, _ = stored_video
    videos = VideoStore(root)
    _, first = search_source(bank_two, "seq", ["silhouette"], frames=4, store_root=root)
    hit = query_cache.read_cache(videos, "seq", 4, 224)
    old = query_cache.CachedQuery(
        hit.frames, hit.has_masks, hit.notes, {"silhouette": np.ones((4, 10), np.float32)}
    )
    query_cache.write_cache(videos, "seq", 4, 224, old, query_cache.video_identity(videos, "seq"))
    _, again = search_source(bank_two, "seq", ["silhouette"], frames=4, store_root=root)
    assert [m.name for m in again.matches] == [m.name for m in first.matches]
    assert query_cache.read_cache(videos, "seq", 4, 224).emb["silhouette"].shape == (4, 576)


def _use_silhouette(monkeypatch, blur: float):
    """Make the process's ``silhouette`` embedder another version of itself: same size (576),
    other embeddings (as other weights of the same network would be)."""
    from zooctl.embed.silhouette import SilhouetteEmbedder
    from zooctl.retrieval import embedder_cache

    monkeypatch.setitem(embedder_cache._EMBEDDERS, ("silhouette", "cpu", ()), SilhouetteEmbedder(blur=blur))


def test_views_record_identities_and_reindexing_one_embedder_keeps_the_others(store, monkeypatch):
    import json

    import jsonschema

    from zooctl.procedural import build_animal
    from zooctl.retrieval.index import index_asset
    from zooctl.store import views_h5
    from zooctl.store.bank import Bank

    bank = Bank(store)
    a = build_animal("quadruped", name="Quad")
    bank.add(a)
    first = index_asset(bank, a, ["silhouette", "effnet"], n_views=3, size=48)
    assert first["identities"]["silhouette"] == "silhouette/24/0.8"
    assert first["identities"]["effnet"].startswith("effnet-lite0/")
    schema = json.loads((Path(__file__).parents[1] / "schemas" / "bank_index.schema.json").read_text())
    jsonschema.validate(json.loads(bank.index_path.read_text()), schema)
    path = views_h5.views_path(store, "Quad")
    sil = views_h5.read_views(path).embeddings["silhouette"]
    # Another silhouette version is now loaded, but reindexing effnet alone copies silhouette's
    # stored embeddings (same views) with their identity: nothing is dropped or silently mixed.
    _use_silhouette(monkeypatch, 1.5)
    again = index_asset(bank, a, ["effnet"], n_views=3, size=48)
    assert set(again["embedders"]) == {"effnet", "silhouette"} and again["views_id"] != first["views_id"]
    assert again["identities"] == first["identities"]
    stored = views_h5.read_views(path)
    np.testing.assert_array_equal(stored.embeddings["silhouette"], sil)
    assert stored.input_kinds == {"effnet": "rgb", "silhouette": "mask"}
    # Other views (4 instead of 3): the kept embedder embeds them again, as it is now.
    four = index_asset(bank, a, ["effnet"], n_views=4, size=48)
    assert four["count"] == 4 and four["identities"]["silhouette"] == "silhouette/24/1.5"
    assert views_h5.read_views(path).embeddings["silhouette"].shape == (4, 576)


def test_views_of_another_version_of_an_embedder_are_refused_or_the_query_reembedded(
    bank_two, stored_video, monkeypatch
):
    """Same-size embeddings of two versions of one embedder (e.g. other CLIP weights) must never be
    compared: a fresh query against old views says reindex; once the bank is reindexed, a video's
    cached query of the old version is embedded again; a half-reindexed bank is refused."""
    import pytest

    from zooctl.retrieval import query_cache
    from zooctl.retrieval.index import index_asset
    from zooctl.retrieval.search import EmbedderMismatch, score_bank, search_source
    from zooctl.store.videos import VideoStore

    root, _ = stored_video
    videos = VideoStore(root)
    _, first = search_source(bank_two, "seq", ["silhouette"], frames=4, store_root=root)
    assert query_cache.read_cache(videos, "seq", 4, 224).identities == {"silhouette": "silhouette/24/0.8"}
    new = "silhouette/24/1.5"
    with pytest.raises(EmbedderMismatch, match="2 of the bank's assets") as exc:
        score_bank(bank_two, _query(), {"silhouette": new})
    assert "bank reindex --embedder silhouette" in exc.value.hint
    _use_silhouette(monkeypatch, 1.5)
    index_asset(bank_two, bank_two.get("Quad"), ["silhouette"], n_views=3, size=48)
    with pytest.raises(EmbedderMismatch, match="2 different versions"):
        score_bank(bank_two, _query())  # no identity known for the query: the bank alone is mixed
    with pytest.raises(EmbedderMismatch, match="1 of the bank's assets"):
        score_bank(bank_two, _query(), {"silhouette": new})
    index_asset(bank_two, bank_two.get("Noodle"), ["silhouette"], n_views=3, size=48)
    _, again = search_source(bank_two, "seq", ["silhouette"], frames=4, store_root=root)
    assert query_cache.read_cache(videos, "seq", 4, 224).identities == {"silhouette": new}
    assert {m.name for m in again.matches} == {m.name for m in first.matches}
