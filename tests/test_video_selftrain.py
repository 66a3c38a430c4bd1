"""The self-training segmenter: its classifier, its feature grid, what it learns from a video's
sure pixels, through the segmenter hook and the CLI."""

from __future__ import annotations

import numpy as np
import pytest
from cli_helpers import run_inprocess
from video_helpers import iou, moving_object_video, write_pngs

from zooctl.errors import InputError, UsageError
from zooctl.plugins import get_registry
from zooctl.video.flow import DISFlow, compute_video_flow
from zooctl.video.selftrain import (
    FeatureNet,
    SelfTrainedSegmenter,
    _on_grid,
    cell_labels,
    fit_logistic,
    grid_to_pixels,
    log_odds,
    main_animal,
    motion_bins,
)


@pytest.fixture(scope="module")
def synthetic():
    return moving_object_video(t=10, h=96, w=128)


def test_logistic_regression_learns_a_separable_rule():
    rng = np.random.default_rng(0)
    x = rng.normal(size=(400, 5)).astype(np.float32)
    y = (x[:, 1] - 0.5 * x[:, 3] > 0.2).astype(np.float64)
    w, b = fit_logistic(x, y, np.ones(len(y)), l2=0.1)
    assert (((x @ w + b) > 0) == (y > 0)).mean() > 0.97
    assert w[1] > 0 and w[3] < 0 and abs(w[0]) < 0.5 * w[1]
    # sample weights count: a class weighted up is predicted more often
    heavy = np.where(y > 0, 5.0, 1.0)
    w2, b2 = fit_logistic(x, y, heavy * len(y) / heavy.sum(), l2=0.1)
    assert ((x @ w2 + b2) > 0).sum() > ((x @ w + b) > 0).sum()


def test_feature_grid_is_aligned_with_the_pixels():
    """The network's cell i is centred on input pixel stride * i: a peak on the stride-32 grid
    lands on the stride-8 cell at the same input pixel, and from there on the frame's pixel."""
    f = np.zeros((4, 6, 1), np.float32)
    f[2, 3, 0] = 1.0  # input pixel (x 96, y 64)
    g = _on_grid(f, 32, 24, 16)
    assert g.shape == (16, 24, 1)
    assert np.unravel_index(np.argmax(g[..., 0]), g.shape[:2]) == (8, 12)  # 64 / 8, 96 / 8
    grid = np.zeros((16, 24), np.float32)
    grid[8, 12] = 1.0
    px = grid_to_pixels(grid, 384, 256, (192, 128))  # the frame at twice the input size
    y, x = np.unravel_index(np.argmax(px), px.shape)
    assert abs(x - 192) <= 1 and abs(y - 128) <= 1


def test_features_shapes():
    net = FeatureNet(width=128)
    frame = np.random.default_rng(0).integers(0, 255, (72, 128, 3), dtype=np.uint8)
    feats, animal = net.features(frame)
    iw, ih = net.input_size(128, 72)
    assert (iw, ih) == (128, 64)
    assert feats.shape == (ih // 8, iw // 8, 40 + 112 + 320) and feats.dtype == np.float32
    assert animal.shape == (ih // 8, iw // 8) and 0.0 <= animal.min() and animal.max() <= 1.0


def test_sure_cells_keep_away_from_the_outline():
    mask = np.zeros((80, 80), bool)
    mask[20:60, 20:60] = True
    fg, bg, fg_px, bg_px = cell_labels(mask, np.zeros((10, 10), np.float32), band=0.1)
    assert fg_px.sum() < mask.sum() and not (fg_px & ~mask).any()  # inside, shrunk
    assert not (bg_px & mask).any() and (~bg_px & ~mask).sum() > 0  # outside, a band left out
    assert fg[4:6, 4:6].all() and not fg[0].any() and bg[0].all() and not bg[3:7, 3:7].any()
    # an empty frame teaches background only where the animal map sees nothing
    seen = np.zeros((10, 10), np.float32)
    seen[2, 2] = 0.9
    fg, bg, _, _ = cell_labels(np.zeros((80, 80), bool), seen, band=0.1)
    assert not fg.any() and not bg[2, 2] and bg.sum() == 99


def test_main_animal_keeps_the_most_probable_part():
    logit = np.full((40, 40), -3.0, np.float32)
    logit[5:10, 5:10] = 1.0  # small, unsure
    logit[20:35, 20:35] = 4.0  # big, sure
    m = main_animal(logit)
    assert m[25, 25] and not m[7, 7]
    assert not main_animal(np.full((8, 8), -1.0, np.float32)).any()


def test_a_leak_and_a_dropped_part_are_repaired_from_what_the_video_teaches(synthetic):
    """On three of ten frames the tracker's mask has leaked onto the background beside the object
    and dropped a quarter of it; the classifier and colour model learned from the sure pixels of all
    ten frames take the leak out and the part back."""
    from zooctl.video import cues

    frames, truth = synthetic
    flow = compute_video_flow(DISFlow("medium"), frames)
    prior = truth.copy()
    for i in (6, 7, 8):
        x, y, w, h = cues.box_of(truth[i])
        prior[i][y + 4 : y + h - 4, x + w - 4 : x + w + 18] = True
        prior[i][:, x : x + w // 4] = False
    seg = SelfTrainedSegmenter(feature_width=128, feature_every=1)
    out = seg.relabel(frames, prior, flow, lambda d: None)
    assert out.shape == truth.shape and out.dtype == bool
    for i in (6, 7, 8):
        assert iou(prior[i], truth[i]) < 0.6 and iou(out[i], truth[i]) > 0.75, (i, iou(out[i], truth[i]))
    assert min(iou(out[i], truth[i]) for i in range(10) if i not in (6, 7, 8)) > 0.95
    info = seg.report["self_training"]
    assert info["animal_cells"] > 0 and info["background_cells"] > info["animal_cells"]
    assert info["frames_looked_at"] == 10
    # a frame the tracker left empty (the animal out of frame) stays empty: nothing is made up there
    prior[4] = False
    out = seg.relabel(frames, prior, flow, lambda d: None)
    assert not out[4].any() and iou(out[3], truth[3]) > 0.95


def test_motion_bins_tell_an_animal_from_the_panning_ground():
    from video_helpers import moving_object_video

    frames, truth = moving_object_video(t=3, h=96, w=128)
    flow = compute_video_flow(DISFlow("medium"), frames)
    bins = motion_bins(flow.residual(1))
    assert bins.shape == truth[1].shape and bins.dtype == np.uint8
    inside = np.median(bins[truth[1]])
    assert inside >= 5 and np.median(bins[~truth[1]]) <= 1  # 5 px against a 2 px pan: the animal moves
    still = motion_bins(np.zeros((96, 128), np.float32))
    assert not still.any()


def test_log_odds_read_even_odds_where_neither_class_was_seen():
    fg = np.array([0.0, 10, 90, 0])
    bg = np.array([900.0, 90, 10, 0])
    plain, shared = log_odds(fg, bg, 5.0), log_odds(fg, bg, 5.0, share=0.05)
    assert plain[3] > 1.5  # add-one: an unseen bin takes the smaller class's side
    assert abs(shared[3]) < 1e-6 and shared[0] < -3 and shared[2] > 3
    assert np.all(np.abs(log_odds(fg * 1000, bg, 2.0)) <= 2.0)


def test_the_motion_model_drops_still_ground_the_tracker_took_beside_a_moving_animal():
    """A red animal walks right over ground panning left; a strip of reddish ground lies along its
    path and on three frames the tracker's mask took the strip beside it. Colour cannot tell them
    apart, the motion against the camera can."""
    import cv2
    from video_helpers import texture

    t, h, w = 10, 96, 128
    bg = (texture(h, w + 4 * t, 0) * 0.5 + np.array([60, 90, 60])).astype(np.uint8)
    skin = (texture(h, w, 1) * 0.25 + np.array([190, 70, 30])).astype(np.uint8)
    strip = np.zeros(bg.shape[:2], bool)
    strip[62:80, 40:130] = True
    bg[strip] = (texture(h, w + 4 * t, 2)[strip] * 0.25 + np.array([170, 80, 40])).astype(np.uint8)
    frames, truth = np.empty((t, h, w, 3), np.uint8), np.zeros((t, h, w), bool)
    prior = np.zeros((t, h, w), bool)
    for i in range(t):
        f, m = np.ascontiguousarray(bg[:, 2 * i : 2 * i + w]), np.zeros((h, w), np.uint8)
        cv2.ellipse(m, (w // 3 + 3 * i, h // 2), (w // 6, h // 5), 0, 0, 360, 1, -1)
        f[m > 0] = skin[m > 0]
        frames[i], truth[i], prior[i] = f, m > 0, m > 0
        if i in (6, 7, 8):
            beside = cv2.dilate(m, np.ones((1, 41), np.uint8)) > 0
            prior[i] |= strip[:, 2 * i : 2 * i + w] & beside
    flow = compute_video_flow(DISFlow("medium"), frames)

    def took(motion_weight):
        seg = SelfTrainedSegmenter(feature_width=128, feature_every=1, motion_weight=motion_weight)
        out = seg.relabel(frames, prior, flow, lambda d: None)
        return np.mean([iou(out[i], truth[i]) for i in (6, 7, 8)]), min(iou(o, m) for o, m in zip(out, truth))

    (leak_without, _), (leak_with, worst) = took(0.0), took(0.75)
    assert leak_with > leak_without + 0.01 and worst > 0.9, (leak_without, leak_with, worst)


def test_selftrain_through_the_segmenter_hook(synthetic):
    frames, truth = synthetic
    seg = get_registry().get("segmenter", "selftrain").create(feature_width=128)
    assert seg.uses_flow and seg.flow_size(854, 480) == seg.tracker.flow_size(854, 480)
    got = seg.segment(frames)  # no box, flow computed here; frames between looks carried along it
    assert got.shape == truth.shape and got.dtype == bool
    assert np.mean([iou(g, m) for g, m in zip(got, truth)]) > 0.8
    assert "seeding" in seg.report and seg.report["self_training"]["frames_looked_at"] == 4  # 0, 3, 6, 9
    # a box is passed to the tracker, which it seeds
    from zooctl.video import cues

    boxed = seg.segment(frames, box=cues.box_of(truth[0]))
    assert np.mean([iou(g, m) for g, m in zip(boxed, truth)]) > 0.8


def test_selftrain_bad_options_and_inputs(synthetic):
    frames, _ = synthetic
    create = get_registry().get("segmenter", "selftrain").create
    with pytest.raises(UsageError, match="feature_every"):
        create(feature_every=0)
    with pytest.raises(UsageError, match="feature_width"):
        create(feature_width=8)
    with pytest.raises(UsageError, match="motion_weight"):
        create(motion_weight=-1)
    with pytest.raises(UsageError, match="colour_memory"):  # the tracker's options are checked too
        create(colour_memory=2.0)
    with pytest.raises(InputError, match="at least 2 frames"):
        create().segment(frames[:1])
    # nothing moves and nothing looks like an animal: empty masks, as the tracker's, no failure
    still = np.full((3, *frames.shape[1:]), 128, np.uint8)
    assert not create(feature_width=128).segment(still).any()


def test_cli_video_add_with_selftrain(store, synthetic, tmp_path, capsys):
    frames, truth = synthetic
    folder = write_pngs(tmp_path / "clip", frames)
    r = run_inprocess(
        capsys,
        "video",
        "add",
        str(folder),
        "--segmenter",
        "selftrain",
        "--seg-option",
        "feature_every=0",
        "-q",
    )
    assert r.code != 0 and "feature_every must be at least 1" in r.err and "Traceback" not in r.err
    args = ("--segmenter", "selftrain", "--seg-option", "feature_width=128", "-q")
    r = run_inprocess(capsys, "video", "add", str(folder), *args)
    assert r.code == 0, r.err
    from zooctl.store.videos import VideoStore

    rec = VideoStore.open(store).get("clip")
    assert rec.segmenter["name"] == "selftrain"
    assert np.mean([iou(m, t) for m, t in zip(rec.masks, truth)]) > 0.8
