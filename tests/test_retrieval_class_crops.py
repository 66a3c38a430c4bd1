"""The semantic term's classifier sees the animal's square kept within the frame (no smeared
border pixels), stored queries cache those classes (older caches are a miss), and the held-out
render styles of the retrieval benchmark draw what the bank's views never do."""

from __future__ import annotations

import numpy as np
import pytest

from zooctl.retrieval.crop import square_crop


def _scene(h: int = 96, w: int = 128, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.integers(0, 256, (h, w, 3), dtype=np.uint8)


def _corner_mask(h: int = 96, w: int = 128) -> np.ndarray:
    m = np.zeros((h, w), bool)
    m[h - 30 :, :36] = True  # touches the bottom and the left edge
    return m


def test_inside_crop_stays_within_the_frame():
    img, mask = _scene(), _corner_mask()
    out, _ = square_crop(img, mask, 64)
    inside, m_in = square_crop(img, mask, 64, inside=True)
    # past the frame the default crop repeats the border: its bottom rows are all alike
    assert np.array_equal(out[-1], out[-2]) and np.array_equal(out[:, 0], out[:, 1])
    assert not np.array_equal(inside[-1], inside[-2]) and not np.array_equal(inside[:, 0], inside[:, 1])
    assert m_in.any()
    # a square within the frame already: the very same crop
    centre = np.zeros_like(mask)
    centre[30:60, 40:80] = True
    assert np.array_equal(square_crop(img, centre, 64)[0], square_crop(img, centre, 64, inside=True)[0])
    # an animal taller than the frame: the square shrinks to the frame's shorter side
    tall = np.zeros_like(mask)
    tall[:, 20:30] = True
    tall[:, 20:110] |= np.arange(96)[:, None] > 40
    crop, _ = square_crop(img, tall, 48, inside=True)
    rows = [crop[i] for i in (0, 1, -2, -1)]
    assert not np.array_equal(rows[0], rows[1]) and not np.array_equal(rows[2], rows[3])


def test_stored_query_classifies_the_crops_within_the_frame(tmp_path):
    """A stored video whose animal touches the frame's edge: the classes come from the crops kept
    within the frame, the embeddings from the usual crops; cached with them."""
    from video_helpers import moving_object_video, write_png_davis

    from zooctl.retrieval.index import cached_embedder
    from zooctl.retrieval.query import classifier_crops, crops_from_frames
    from zooctl.retrieval.search import query_embeddings
    from zooctl.store.videos import VideoStore
    from zooctl.video.ingest import AddOptions, add_video

    frames, masks = moving_object_video(t=6, h=96, w=128)
    frames, masks = frames[:, 30:], masks[:, 30:]  # the ellipse now touches the top edge
    folder = write_png_davis(tmp_path / "edge", frames, masks)
    root = tmp_path / "store"
    add_video(VideoStore.open(root), folder, AddOptions(name="edge"))
    q, emb, _ = query_embeddings("edge", ["effnet"], k=3, size=64, store_root=root, need_images=True)
    eff = cached_embedder("effnet", "cpu")
    stored = VideoStore(root).get("edge")
    sf, sm = stored.frames[q.frames], stored.masks[q.frames]
    images, _, chosen = crops_from_frames(sf, sm, 3, 64)
    inside = classifier_crops(sf, sm, chosen, 64)
    assert not np.array_equal(inside, images)
    np.testing.assert_allclose(q.classes, eff.classify(inside), atol=1e-5)
    np.testing.assert_allclose(emb["effnet"], eff.embed_batch(images), atol=1e-5)
    again, _, _ = query_embeddings("edge", ["effnet"], k=3, size=64, store_root=root)
    assert again.images.shape[0] == 0 and np.allclose(again.classes, q.classes)  # from the cache


def test_a_cache_of_the_earlier_crops_is_a_miss(tmp_path, monkeypatch):
    """Caches written before the classifier's crops (version 1) are embedded again."""
    from video_helpers import stored_masked_video

    from zooctl.retrieval import query_cache
    from zooctl.retrieval.search import query_embeddings
    from zooctl.store.videos import VideoStore

    root, _ = stored_masked_video(tmp_path)
    videos = VideoStore(root)
    query_embeddings("seq", ["effnet"], k=3, size=64, store_root=root)
    hit = query_cache.read_cache(videos, "seq", 3, 64)
    assert hit is not None
    monkeypatch.setattr(query_cache, "CACHE_VERSION", 1)
    query_cache.write_cache(videos, "seq", 3, 64, hit, query_cache.video_identity(videos, "seq"))
    monkeypatch.undo()
    assert query_cache.read_cache(videos, "seq", 3, 64) is None


@pytest.fixture(scope="module")
def quadruped():
    from zooctl.procedural import starter_assets

    return starter_assets(plans=["quadruped"], variants=False)[0]


def test_heldout_styles_draw_what_the_views_do_not(quadruped):
    from zooctl.retrieval.evaluate import render_query_video
    from zooctl.retrieval.styles import HELDOUT_STYLES

    plain = render_query_video(quadruped, n_frames=2, size=64, seed=3, render_size=96)
    again = render_query_video(quadruped, n_frames=2, size=64, seed=3, render_size=96)
    assert np.array_equal(plain.images, again.images)
    for style in HELDOUT_STYLES:
        q = render_query_video(quadruped, n_frames=2, size=64, seed=3, render_size=96, style=style)
        assert q.images.shape == plain.images.shape
        assert np.abs(q.images.astype(int) - plain.images).mean() > 2, style
        if style != "below":  # the same camera: the same silhouette
            assert np.array_equal(q.masks, plain.masks), style
        again = render_query_video(quadruped, n_frames=2, size=64, seed=3, render_size=96, style=style)
        assert np.array_equal(q.images, again.images), style
    with pytest.raises(ValueError, match="unknown render style"):
        render_query_video(quadruped, n_frames=2, size=64, seed=3, render_size=96, style="sepia")
