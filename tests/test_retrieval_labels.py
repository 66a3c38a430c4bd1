"""Bank assets' animal labels (given, from the name or tags, from the rendered views), kept by
`bank label`, `bank repair` and export; the semantic term of the search and its explanation; the
fit's trials try the best asset of the video's family."""

from __future__ import annotations

import json

import jsonschema
import numpy as np
import pytest
from cli_helpers import REPO, run_inprocess
from gltf_builder import write_tiny_glb

from zooctl.retrieval.semantic import (
    class_distribution,
    confidence,
    matched_taxon,
    query_taxon,
    relative_scores,
    semantic_scores,
    views_taxon,
)
from zooctl.retrieval.taxonomy import load_taxonomy


def schema(name):
    return json.loads((REPO / "schemas" / f"{name}.schema.json").read_text())


@pytest.fixture
def bank_env(store, monkeypatch):
    monkeypatch.setenv("ZOOCTL_VIEWS", "0")
    return store


def _add(capsys, path, *args):
    r = run_inprocess(capsys, "bank", "add", str(path), *args)
    assert r.code == 0, r.err
    return r


def test_label_from_name_given_and_tags(bank_env, capsys, tmp_path):
    from zooctl.store.bank import Bank

    _add(capsys, write_tiny_glb(tmp_path / "Red_Foxes_walk.glb"))
    _add(capsys, write_tiny_glb(tmp_path / "model_01.glb"), "--label", "Shiba Inu")
    _add(capsys, write_tiny_glb(tmp_path / "model_02.glb"), "--tag", "quadruped", "--tag", "horse")
    _add(capsys, write_tiny_glb(tmp_path / "model_03.glb"))
    bank = Bank(bank_env)
    entries = {e["name"]: e for e in bank.list()}
    assert (entries["Red_Foxes_walk"]["label"], entries["Red_Foxes_walk"]["label_source"]) == (
        "red fox",
        "name",
    )
    assert (entries["model_01"]["label"], entries["model_01"]["label_source"]) == ("Shiba Inu", "given")
    assert (entries["model_02"]["label"], entries["model_02"]["label_source"]) == ("horse", "tags")
    assert "label" not in entries["model_03"]  # nothing names an animal and it has no views
    jsonschema.validate(json.loads(bank.index_path.read_text()), schema("bank_index"))
    for n in entries:
        jsonschema.validate(json.loads(bank.card_path(n).read_text()), schema("asset_card"))
    assert bank.get("model_01").meta["label"] == "Shiba Inu"  # in the asset file itself
    r = run_inprocess(capsys, "bank", "show", "model_01")
    assert "label: Shiba Inu (domestic dog > Canidae > Carnivora > quadruped; given)" in r.out
    r = run_inprocess(capsys, "bank", "list")
    assert "red fox" in r.out and "label" in r.out


def test_bad_label_is_one_clear_line(bank_env, capsys, tmp_path):
    r = run_inprocess(capsys, "bank", "add", str(write_tiny_glb(tmp_path / "a.glb")), "--label", "florp")
    assert r.code != 0 and "'florp' names no animal zooctl knows" in r.err and "Traceback" not in r.err
    from zooctl.store.bank import Bank

    assert not Bank(bank_env).exists("a")


def test_bank_label_sets_keeps_views_and_survives_repair_and_export(bank_env, capsys, tmp_path, monkeypatch):
    from zooctl.store.bank import Bank

    monkeypatch.setenv("ZOOCTL_VIEWS", "1")
    _add(capsys, write_tiny_glb(tmp_path / "thing.glb"), "--label", "cow")
    bank = Bank(bank_env)
    views_id = bank.summary("thing")["views"]["views_id"]
    r = run_inprocess(capsys, "bank", "label", "thing", "grey wolf", "--json")
    assert r.code == 0, r.err
    assert r.json() == {"name": "thing", "label": "grey wolf", "label_source": "given"}
    entry = bank.summary("thing")
    assert entry["label"] == "grey wolf" and entry["views"]["views_id"] == views_id
    assert json.loads(bank.card_path("thing").read_text())["label"] == "grey wolf"
    assert bank.get("thing").meta["label"] == "grey wolf"
    # the views are still current: search finds them without a reindex
    from zooctl.retrieval.search import load_packs

    packs, notes = load_packs(bank, ["effnet"])
    assert "thing" in packs["effnet"].names and not notes
    # repair from the asset files alone keeps the label
    bank.index_path.unlink()
    assert run_inprocess(capsys, "bank", "repair").code == 0
    assert bank.summary("thing")["label"] == "grey wolf" and "views" in bank.summary("thing")
    # export writes it into the glTF's asset extras
    out = tmp_path / "thing_out.glb"
    assert run_inprocess(capsys, "bank", "export", "thing", "-o", str(out)).code == 0
    from zooctl.io.gltf_import import load_gltf

    assert load_gltf(out, "x").meta.get("label") == "grey wolf"
    # a label no animal matches is refused; a missing asset too
    assert run_inprocess(capsys, "bank", "label", "thing", "florp").code != 0
    assert run_inprocess(capsys, "bank", "label", "nothing", "fox").code != 0


def test_bank_label_without_label_infers_again(bank_env, capsys, tmp_path):
    from zooctl.store.bank import Bank

    _add(capsys, write_tiny_glb(tmp_path / "Horse.glb"), "--label", "cat")
    r = run_inprocess(capsys, "bank", "label", "Horse")
    assert r.code == 0 and Bank(bank_env).summary("Horse")["label"] == "horse"
    _add(capsys, write_tiny_glb(tmp_path / "blob.glb"))
    r = run_inprocess(capsys, "bank", "label", "blob")  # no name, no tags, no views
    assert r.code != 0 and "bank label blob" in r.err


def _probs(mass: dict[int, float]) -> np.ndarray:
    p = np.zeros(1000)
    for i, v in mass.items():
        p[i] = v
    p[500] = 1 - p.sum()  # the rest on a non-animal class
    return p


def test_views_taxon_takes_the_deepest_majority():
    assert views_taxon(_probs({207: 0.3, 208: 0.3})).name == "domestic dog"  # two breeds, one species
    assert views_taxon(_probs({277: 0.3, 269: 0.3})).name == "Canidae"  # fox and wolf
    assert views_taxon(_probs({277: 0.3, 294: 0.3})).name == "Carnivora"  # fox and bear
    assert views_taxon(_probs({277: 0.3, 345: 0.3})).name == "quadruped"  # fox and ox
    assert views_taxon(_probs({277: 0.3, 100: 0.3})) is None  # a fox and a swan: no majority
    assert views_taxon(_probs({})) is None  # no animal at all


def test_semantic_scores_follow_the_taxonomy():
    tax = load_taxonomy()
    crops = np.stack([_probs({345: 0.8}), _probs({345: 0.4, 346: 0.2})])  # ox, ox + water buffalo
    dist = class_distribution(crops)
    taxa = [tax.lookup(x) for x in ("cow", "bison", "deer", "fox", "black swan")] + [None]
    s = semantic_scores(dist, taxa)
    # the nearest relative of each class takes its probability: the cow the oxen, the cow and the
    # bison (both its family) the water buffalo; the deer (only the order) nothing
    np.testing.assert_allclose(s, [0.7, 0.1, 0, 0, 0, 0], atol=1e-9)
    assert query_taxon(dist).name == "cattle"
    assert matched_taxon(dist, taxa[2]) == ("order", "Artiodactyla")
    # without the cow and the bison the deer is the nearest: the order takes the family's place
    assert semantic_scores(dist, taxa[2:])[0] == pytest.approx(0.7)
    # a query the classifier does not take for an animal weighs little: confidence-weighted
    weak = class_distribution(np.stack([_probs({345: 0.05})]))
    assert semantic_scores(weak, taxa[:1])[0] < 0.1 * s[0]


def test_semantic_term_falls_back_to_the_nearest_order():
    """A bear in a bank without bears: the carnivores (its order) take it, not an asset labelled
    only with the body plan; an elephant with no asset of its order: every quadruped alike."""
    tax = load_taxonomy()
    taxa = [tax.resolve(x) for x in ("quadruped", "red fox", "grey wolf", "cow", "bird")]
    bear = class_distribution(np.stack([_probs({294: 0.6, 295: 0.1, 277: 0.05, 345: 0.05})]))
    s = semantic_scores(bear, taxa)
    np.testing.assert_allclose(s, [0, 0.75, 0.7, 0.05, 0], atol=1e-9)
    rel = relative_scores(bear, s)
    assert rel[1] == pytest.approx(confidence(bear)) and rel[0] == 0  # the fox: the family's 0.7
    elephant = class_distribution(np.stack([_probs({385: 0.5, 386: 0.3})]))
    s = semantic_scores(elephant, taxa)
    np.testing.assert_allclose(s, [0.8, 0.8, 0.8, 0.8, 0], atol=1e-9)


def test_search_semantic_term_and_family_in_trials(tmp_path):
    """A bank whose appearance ranks the cow last: the semantic term lifts it, and the fit's
    candidates put the best asset of the video's family within the trials whatever its rank."""
    from zooctl.retrieval.benchmark import synthetic_bank
    from zooctl.retrieval.search import score_bank
    from zooctl.store.bank import Bank

    synthetic_bank(tmp_path, 12, {"effnet": 16}, n_views=3)
    bank = Bank(tmp_path)
    names = bank.names()
    for n, label in zip(names, ["fox", "grey wolf", "quadruped", "horse"]):
        bank.update_summary(n, label=label, label_source="given")
    cow = names[-1]
    bank.update_summary(cow, label="cow", label_source="given")
    from zooctl.store import views_h5

    pack = views_h5.read_pack(tmp_path, "effnet")
    q = np.asarray(pack.emb[names.index(names[5]), :2], np.float32)  # looks like asset 5
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    classes = np.stack([_probs({345: 0.7}), _probs({345: 0.6, 339: 0.1})])  # an ox
    plain = score_bank(bank, {"effnet": q}, classes=classes, semantic_weight=0)
    assert plain.matches[0].name == names[5] and plain.semantic_weight is None
    sem = score_bank(bank, {"effnet": q}, classes=classes, semantic_weight=100)
    assert sem.matches[0].name == cow and sem.matches[0].taxon == ["species", "cattle"]
    assert sem.classes[0][0] == "ox" and sem.matches[0].terms["semantic"] < 0
    unlabelled = [m for m in sem.matches if m.label is None]
    assert unlabelled and all(m.semantic == 0 for m in unlabelled)  # they compete on appearance alone
    from zooctl.retrieval.explain import explain_lines, explain_table

    lines = explain_lines(sem)
    assert lines[0].startswith("the video looks like") and "ox 0.65" in lines[0]
    assert f"#1 {cow} (cow) shares the species cattle." in lines
    cols, rows, _ = explain_table(sem)
    assert ("shares", "left") in cols and rows[0][-2] == "species cattle"


def test_trials_include_the_best_asset_of_the_family():
    from zooctl.fit.template import promote_kin
    from zooctl.retrieval.search import Match

    def m(name, taxon=None):
        return Match(name, 0.0, {}, 0, [], taxon=taxon)

    ranked = [
        m("Bull", ["order", "Artiodactyla"]),
        m("Snake"),
        m("Whale"),
        m("Wolf", ["family", "Canidae"]),
        m("Fox", ["family", "Canidae"]),
    ]
    out = [x.name for x in promote_kin(ranked, 3)]
    assert out == ["Bull", "Snake", "Wolf", "Whale", "Fox"]  # the first of the family, into the trials
    assert [x.name for x in promote_kin(ranked, 4)] == [x.name for x in ranked]  # already tried
    assert [x.name for x in promote_kin(ranked[:3], 2)] == ["Bull", "Snake", "Whale"]  # no family: as ranked


def test_trials_weigh_what_the_classifier_sees():
    """A trial that fits the input view a little better does not win over a candidate the
    classifier is sure of (a dog against a duck-billed dinosaur seen side on); without semantic
    scores, or with scores the classifier is unsure of, the trial IoU decides as before."""
    from zooctl.fit.template import pick_trial, trial_score

    def pick(ious, semantic):
        return pick_trial([trial_score(i, s) for i, s in zip(ious, semantic, strict=True)])

    ious = [0.834, 0.798, 0.860]
    assert pick_trial(ious) == 2
    assert pick(ious, [0.89, 0.01, 0.0]) == 0
    assert pick(ious, [0.1, 0.0, 0.0]) == 2  # a stylised render: little confidence
    assert pick([0.90, 0.80], [0.0, 0.9]) == 0  # a far worse fit still loses


def test_stored_query_caches_its_classes(tmp_path):
    """The query's ImageNet probabilities come from the same pass as its effnet embeddings and are
    cached with them; a cache written before them is embedded again once."""
    from video_helpers import stored_masked_video

    from zooctl.retrieval import query_cache
    from zooctl.retrieval.search import query_embeddings
    from zooctl.store.videos import VideoStore

    root, _ = stored_masked_video(tmp_path)
    videos = VideoStore(root)
    q1, e1, _ = query_embeddings("seq", ["effnet"], k=3, size=64, store_root=root)
    assert q1.classes.shape == (3, 1000) and np.allclose(q1.classes.sum(1), 1, atol=1e-4)
    q2, _, _ = query_embeddings("seq", ["effnet"], k=3, size=64, store_root=root)
    assert q2.images.shape[0] == 0 and np.allclose(q2.classes, q1.classes)  # from the cache
    old = query_cache.read_cache(videos, "seq", 3, 64)
    old.classes = None  # as a cache from before the semantic term
    query_cache.write_cache(videos, "seq", 3, 64, old, query_cache.video_identity(videos, "seq"))
    q3, e3, _ = query_embeddings("seq", ["effnet"], k=3, size=64, store_root=root)
    assert q3.images.shape[0] == 3 and np.allclose(q3.classes, q1.classes, atol=1e-5)
    np.testing.assert_allclose(e3["effnet"], e1["effnet"], atol=1e-5)
    assert query_cache.read_cache(videos, "seq", 3, 64).classes is not None


def test_reindex_labels_an_asset_stored_before_labels(store, capsys, tmp_path, monkeypatch):
    from zooctl.io.gltf_import import load_gltf
    from zooctl.store.bank import Bank

    bank = Bank(store)
    bank.add(load_gltf(write_tiny_glb(tmp_path / "Wolf.glb"), "Wolf"))  # as an older zooctl stored it
    assert "label" not in bank.summary("Wolf")
    monkeypatch.setenv("ZOOCTL_EMBEDDERS", "silhouette")
    r = run_inprocess(capsys, "bank", "reindex", "Wolf")
    assert r.code == 0, r.err
    entry = bank.summary("Wolf")
    assert (entry["label"], entry["label_source"]) == ("grey wolf", "name") and "views" in entry
