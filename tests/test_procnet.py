"""Random procedural animals, the procnet training job, its embedder and its CLI."""

from __future__ import annotations

import numpy as np
import pytest
from cli_helpers import run_inprocess

from zooctl.embed.procnet import ProcnetEmbedder, default_weights
from zooctl.errors import InputError
from zooctl.procedural.random import LABELS, RANGES, random_assets, random_params
from zooctl.retrieval.index import embed_inputs
from zooctl.retrieval.train_data import render_training_set
from zooctl.retrieval.train_embedder import TrainConfig, save_model, supcon, train_head


def test_random_animals_are_deterministic_labelled_and_in_range():
    a, b = random_assets(len(LABELS), seed=3), random_assets(len(LABELS), seed=3)
    assert [x.meta["body_plan"] for x in a] == list(LABELS)
    for x, y in zip(a, b, strict=True):
        assert x.name == y.name and np.array_equal(x.vertices, y.vertices)
    c = random_assets(len(LABELS), seed=4)
    assert not np.allclose(a[0].vertices.max(0), c[0].vertices.max(0))
    rng = np.random.default_rng(0)
    for label, (_, ranges) in RANGES.items():
        p = random_params(rng, label)
        for k, (lo, hi) in ranges.items():
            assert lo <= getattr(p, k) <= hi, (label, k)


def test_every_benchmark_body_plan_has_random_animals_of_its_shape():
    from zooctl.retrieval.evaluate import BODY_PLANS

    assert set(BODY_PLANS.values()) <= set(LABELS)
    for i, label in enumerate(("biped dinosaur", "humanoid", "crab")):
        for a in random_assets(3, seed=i, labels=[label]):
            ext = np.ptp(a.vertices, axis=0)  # x across, y up, z along
            feet = [n for n in a.joint_names if "foot" in n]
            if label == "biped dinosaur":  # level body, long tail, two legs and two arms
                assert ext[2] > 1.5 * ext[1] and len(feet) == 2 and "upperarm_l" in a.joint_names
                assert a.vertices[:, 2].max() > 0.5 * ext[2] - 0.1  # most of the length behind the hips
            elif label == "humanoid":  # upright, two legs, two arms, a head on top
                assert ext[1] > 1.5 * ext[2] and len(feet) == 2 and "upperarm_r" in a.joint_names
            else:  # wide and flat, eight legs and two claws
                assert ext[0] > 2 * ext[1] and len(feet) == 8
                assert {"claw_finger_l", "claw_finger_r"} <= set(a.joint_names)
            assert a.meta["body_plan"] == label


def test_supcon_prefers_embeddings_grouped_by_label():
    import torch

    lab = torch.tensor([0, 0, 1, 1])
    good = torch.nn.functional.normalize(torch.tensor([[1.0, 0], [1, 0.1], [0, 1], [0.1, 1]]), dim=1)
    bad = good[[0, 2, 1, 3]]
    assert supcon(good, lab, 0.1) < supcon(bad, lab, 0.1)


@pytest.fixture(scope="module")
def tiny_set():
    return render_training_set(8, 2, seed=0, size=64)


def test_tiny_training_is_deterministic_and_loads_as_an_embedder(tiny_set, tmp_path):
    assert len(tiny_set) == 16 and tiny_set.features["effnet"].shape == (16, 1280)
    assert tiny_set.features["silhouette"].shape == (16, 576)
    cfg = TrainConfig(hidden=32, dim=16, steps=4, animals_per_batch=8, views_per_animal=2)
    w1, l1 = train_head(tiny_set, cfg)
    w2, l2 = train_head(tiny_set, cfg)
    assert l1 == l2 and all(np.array_equal(w1[k], w2[k]) for k in w1)
    assert np.isfinite(l1).all()
    p = save_model(tmp_path / "a.npz", w1, cfg, tiny_set, {})
    emb = ProcnetEmbedder(weights=p)
    assert emb.dim == 16 and emb.input_kind == "rgb+mask"
    rng = np.random.default_rng(0)
    imgs = rng.integers(0, 255, (3, 64, 64, 3), dtype=np.uint8)
    masks = np.zeros((3, 64, 64), bool)
    masks[:, 16:48, 20:40] = True
    e = embed_inputs(emb, imgs, masks)
    assert e.shape == (3, 16) and np.allclose(np.linalg.norm(e, axis=1), 1, atol=1e-5)
    # other weights, other identity: banks embedded by the old ones are told to reindex
    w3, _ = train_head(tiny_set, TrainConfig(hidden=32, dim=16, steps=4, seed=1, animals_per_batch=8))
    q = save_model(tmp_path / "b.npz", w3, cfg, tiny_set, {})
    assert ProcnetEmbedder(weights=q).identity != emb.identity
    with pytest.raises(Exception, match="need|masks"):
        embed_inputs(emb, imgs, None)


def test_bank_views_join_training_with_unknown_plans(tiny_set):
    import torch

    from zooctl.retrieval.train_data import TrainingSet
    from zooctl.retrieval.train_embedder import merge_sets

    z = torch.nn.functional.normalize(torch.randn(6, 4, generator=torch.Generator().manual_seed(0)), dim=1)
    lab = torch.tensor([0, 0, 1, 1, -1, -1])
    # unknown rows are no anchors and no positives, but still negatives; none known: no loss
    moved = z.clone()
    moved[4:] = -moved[4:]
    assert supcon(z, lab, 0.1) != supcon(moved, lab, 0.1)  # negatives still count
    assert float(supcon(z, torch.full((6,), -1), 0.1)) == 0.0
    rows = np.arange(6)
    bank = TrainingSet(
        {f: tiny_set.features[f][rows] for f in tiny_set.features},
        np.array([0, 0, -1, -1, 1, 1]),
        np.array([0, 0, 1, 1, 2, 2]),
        [tiny_set.labels[1], tiny_set.labels[0]],  # another label order: mapped by name
    )
    merged, ids = merge_sets(tiny_set, bank)
    assert len(merged) == len(tiny_set) + 6 and list(ids) == [8, 9, 10]
    assert list(merged.label[-6:]) == [1, 1, -1, -1, 0, 0]
    cfg = TrainConfig(hidden=32, dim=16, steps=3, animals_per_batch=8, views_per_animal=2, bank_fraction=0.5)
    w0, _ = train_head(tiny_set, cfg)
    w1, l1 = train_head(tiny_set, cfg, bank=bank, init=w0)
    w2, l2 = train_head(tiny_set, cfg, bank=bank, init=w0)
    assert l1 == l2 and np.isfinite(l1).all() and not np.array_equal(w1["w1"], w0["w1"])


def test_without_weights_it_says_how_to_train_them(tmp_path, monkeypatch):
    monkeypatch.delenv("ZOOCTL_PROCNET_WEIGHTS", raising=False)
    monkeypatch.setenv("ZOOCTL_STORE", str(tmp_path / "store"))
    assert default_weights() == tmp_path / "store" / "models" / "procnet.npz"
    with pytest.raises(InputError, match="procnet weights") as e:
        ProcnetEmbedder()
    assert "embed train" in e.value.hint
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(InputError, match="not a procnet weights file"):
        ProcnetEmbedder(weights=tmp_path / "bad.npz")


def test_cli_trains_and_refuses_bad_input(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("ZOOCTL_STORE", str(tmp_path / "store"))
    out = tmp_path / "m.npz"
    r = run_inprocess(
        capsys, "embed", "train", "--animals", "8", "--views", "2", "--steps", "3", "-o", str(out), "--json"
    )
    assert r.code == 0, r.err
    assert r.json()["steps_run"] == 3 and out.is_file()
    assert out.with_suffix(".loss.png").read_bytes()[:4] == b"\x89PNG"
    r = run_inprocess(capsys, "embed", "train", "--animals", "2")
    assert r.code != 0 and "--animals" in r.err and "Traceback" not in r.err
    r = run_inprocess(capsys, "bank", "seed", "--random", "2", "--plan", "dragon", "--no-views")
    assert r.code != 0 and "unknown body plan" in r.err
    r = run_inprocess(capsys, "bank", "seed", "--random", "2", "--seed", "1", "--no-views", "--json")
    assert r.code == 0 and len(r.json()["added"]) == 2
    r = run_inprocess(capsys, "embed", "train", "--animals", "8", "--views", "2", "--bank")
    assert r.code == 2 and "no asset in the bank has views" in r.err and "Traceback" not in r.err


def test_cli_adapts_to_the_bank(tmp_path, capsys, monkeypatch):
    from zooctl.retrieval.train_bank import plan_from_tags

    labels = list(LABELS)
    assert plan_from_tags(["quaternius", "Biped-Dinosaur"], labels) == "biped dinosaur"
    assert plan_from_tags(["procedural", "dinosaur"], labels) == "biped dinosaur"  # a starter plan
    assert plan_from_tags(["quaternius"], labels) is None
    monkeypatch.setenv("ZOOCTL_STORE", str(tmp_path / "store"))
    monkeypatch.setenv("ZOOCTL_VIEWS", "1")
    r = run_inprocess(capsys, "bank", "seed", "--plan", "crab", "--no-variants")
    assert r.code == 0, r.err
    r = run_inprocess(capsys, "bank", "seed", "--random", "1", "--plan", "fish")
    assert r.code == 0, r.err
    args = ["embed", "train", "--animals", "8", "--views", "2", "--steps", "2", "--json"]
    r = run_inprocess(capsys, *args, "--bank", "--bank-steps", "2")
    assert r.code == 0, r.err
    out = r.json()
    assert out["bank"] == {"assets": 2, "tagged": 2, "steps": 2} and out["steps_run"] == 4


def test_frozen_feature_evaluation_scores_leave_one_out(tmp_path, tiny_set):
    from zooctl.retrieval.procnet_eval import FrozenFeatures, evaluate_weights, load_features, save_features

    rng = np.random.default_rng(0)
    plans = ["fish", "fish", "snake", "snake", "crab"]  # crab: unanswerable

    def feats(n_views: int, noise: float) -> dict[str, np.ndarray]:
        out = {}
        for f, D in (("effnet", 1280), ("silhouette", 576)):
            centre = {p: rng.normal(size=D) for p in set(plans)}
            x = np.stack([centre[p] + noise * rng.normal(size=(n_views, D)) for p in plans])
            out[f] = (x / np.linalg.norm(x, axis=-1, keepdims=True)).astype(np.float32)
        return out

    rng = np.random.default_rng(1)
    bank = feats(4, 0.3)
    rng = np.random.default_rng(1)  # the same plan centres for the queries
    query = feats(2, 0.3)
    ff = FrozenFeatures(
        list("ABCDE"), plans, bank, query, [], [], {f: v[:0] for f, v in bank.items()}, tiny_set
    )
    ff = load_features(save_features(tmp_path / "f.npz", ff))
    w, _ = train_head(
        tiny_set, TrainConfig(hidden=16, dim=8, steps=2, animals_per_batch=8, views_per_animal=2)
    )
    path = save_model(tmp_path / "w.npz", w, TrainConfig(hidden=16, dim=8), tiny_set, {})
    rows = {(r["set"], r["embedders"]): r for r in evaluate_weights(ff, path)["rows"]}
    default = rows[("shared", "effnet+silhouette")]
    assert default["queries"] == 5 and default["answerable"] == 4
    assert default["top1_answerable"] == 4 and default["misses"] == [f"E->{default['misses'][0][3:]}"]
    assert rows[("held-out", "procnet")]["queries"] == len(np.unique(tiny_set.animal))
    assert ("shared+starter", "effnet+silhouette+procnet") in rows
