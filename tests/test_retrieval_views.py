"""Bank views: seeded random renders cropped like queries, the sidecar store, and search packs."""

from __future__ import annotations

import numpy as np
import pytest

from zooctl.errors import UsageError
from zooctl.retrieval.crop import mask_box, square_crop


@pytest.fixture(scope="module")
def animal():
    from zooctl.procedural import build_animal

    return build_animal("quadruped", name="Quad")


def test_square_crop_centres_the_mask():
    img = np.zeros((100, 200, 3), np.uint8)
    mask = np.zeros((100, 200), bool)
    mask[20:40, 120:180] = True  # 60 x 20 box
    img[mask] = 255
    out, m = square_crop(img, mask, 64, margin=0.0)
    assert out.shape == (64, 64, 3) and m.shape == (64, 64)
    x0, y0, x1, y1 = mask_box(m)
    assert x0 <= 1 and x1 >= 63  # the long side fills the crop
    assert abs((y0 + y1) / 2 - 32) <= 1  # centred vertically
    assert abs((y1 - y0) - 64 / 3) <= 2
    assert square_crop(img, np.zeros_like(mask), 64) is None


def test_views_are_seeded_varied_and_cropped(animal):
    from zooctl.retrieval.views import render_views

    a = render_views(animal, n_views=4, size=64, seed=3)
    b = render_views(animal, n_views=4, size=64, seed=3)
    c = render_views(animal, n_views=4, size=64, seed=4)
    assert a.images.shape == (4, 64, 64, 3) and a.masks.shape == (4, 64, 64)
    np.testing.assert_array_equal(a.images, b.images)
    assert not np.array_equal(a.images, c.images)
    for m in a.masks:
        x0, y0, x1, y1 = mask_box(m)
        assert max(x1 - x0, y1 - y0) >= 64 * 0.8  # the animal fills its crop
    assert len({round(float(x)) for x in a.params["azimuth"]}) == 4
    assert set(a.params) >= {"clip", "frame", "azimuth", "elevation", "fov", "light"}
    with pytest.raises(UsageError):
        render_views(animal, n_views=0)


def test_joint_perturbation_changes_the_pose(animal):
    from zooctl.retrieval.views import sample_poses

    rng = np.random.default_rng(0)
    still, _, _ = sample_poses(animal, np.random.default_rng(0), 3, sigma_deg=0)
    moved, _, _ = sample_poses(animal, rng, 3, sigma_deg=10)
    assert not np.allclose(still, moved)
    roots = animal.parents < 0
    np.testing.assert_allclose(still[:, roots], moved[:, roots])  # roots are left to the camera
    R = moved[..., :3, :3]
    assert np.all(np.isfinite(R))


def test_sidecar_round_trip_and_pack(store, animal):
    from zooctl.retrieval.index import current_pack, index_asset, views_entries
    from zooctl.store import views_h5
    from zooctl.store.bank import Bank

    bank = Bank(store)
    bank.add(animal)
    entry = index_asset(bank, animal, ["silhouette"], n_views=5, size=48)
    assert entry["count"] == 5 and entry["embedders"] == {"silhouette": 576}
    assert views_entries(bank)["Quad"]["views_id"] == entry["views_id"]
    sv = views_h5.read_views(views_h5.views_path(store, "Quad"), images=True, masks=True)
    assert sv.images.shape == (5, 48, 48, 3) and sv.masks.shape == (5, 48, 48) and sv.masks.any()
    assert sv.embeddings["silhouette"].shape == (5, 576)
    assert sv.asset_digest == views_h5.summary_digest(bank.summary("Quad"))
    pack, missing = current_pack(bank, "silhouette")
    assert pack.names == ["Quad"] and missing == [] and pack.emb.shape == (1, 5, 576)
    np.testing.assert_allclose(pack.emb[0].astype(np.float32), sv.embeddings["silhouette"], atol=1e-3)
    # a second asset makes the pack stale: it is rebuilt with both
    from zooctl.procedural import build_animal

    fish = build_animal("fish", name="Fishy")
    bank.add(fish)
    pack2, missing = current_pack(bank, "silhouette")
    assert pack2.names == ["Quad"] and missing == ["Fishy"]
    index_asset(bank, fish, ["silhouette"], n_views=3, size=48)
    pack3, missing = current_pack(bank, "silhouette")
    assert pack3.names == ["Fishy", "Quad"] and list(pack3.counts) == [3, 5] and missing == []
    assert not pack3.emb[0, 3:].any()  # padding rows
    # re-adding an asset drops its views from the index (they described the old asset)
    bank.add(fish, replace=True)
    assert "Fishy" not in views_entries(bank)
    pack4, missing = current_pack(bank, "silhouette")
    assert pack4.names == ["Quad"] and missing == ["Fishy"]
    # only one pack data file pair is kept
    assert len(list((store / "bank" / "views").glob("pack-silhouette-*.npy"))) == 2


def test_views_schema_documents_the_sidecar(store, animal):
    import json

    from conftest import REPO

    from zooctl.retrieval.index import index_asset
    from zooctl.store.bank import Bank
    from zooctl.store.h5 import describe_h5

    jsonschema = pytest.importorskip("jsonschema")
    bank = Bank(store)
    bank.add(animal)
    index_asset(bank, animal, ["silhouette"], n_views=2, size=40)
    schema = json.loads((REPO / "schemas" / "asset_views.schema.json").read_text())
    jsonschema.validate(describe_h5(store / "bank" / "views" / "Quad.h5"), schema)
