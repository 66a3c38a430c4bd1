"""The learned segmenter: its synthetic composites, the numpy head against the torch one it was
trained as, training end to end, the segmenter through the hook, and `zooctl segment train`."""

from __future__ import annotations

import numpy as np
import pytest
from cli_helpers import run_inprocess
from video_helpers import iou, moving_object_video

from zooctl.errors import InputError
from zooctl.plugins import get_registry


@pytest.fixture(scope="module")
def animals():
    from zooctl.procedural.random import random_assets

    return random_assets(3, seed=1, any_hue=True)


def test_composites_hold_an_animal_its_mask_and_a_moving_second_frame(animals):
    from zooctl.benchdata.composites import composite

    rng = np.random.default_rng(3)
    shown = 0
    for _ in range(6):
        s = composite(animals, rng, (96, 72))
        assert s.frames.shape == (2, 72, 96, 3) and s.frames.dtype == np.uint8
        assert s.mask.shape == (72, 96) and s.mask.dtype == bool
        shown += int(s.mask.any())
        assert not np.array_equal(s.frames[0], s.frames[1])  # the camera pans, the animal moves
    assert shown >= 5  # an occluder or a far corner may hide one, not most
    # the same seed gives the same sample (training sets are reproducible)
    a = composite(animals, np.random.default_rng(9), (96, 72))
    b = composite(animals, np.random.default_rng(9), (96, 72))
    assert np.array_equal(a.frames, b.frames) and np.array_equal(a.mask, b.mask)


def test_numpy_head_matches_the_torch_model_it_was_trained_as(tmp_path):
    import torch

    from zooctl.pipelines.segment_train import _model, save_weights
    from zooctl.video.animalnet import IN_CHANNELS, AnimalNet

    torch.manual_seed(0)
    p = 20
    model = _model(p + 1)
    for prm in model.parameters():  # not the initialisation's near-zero biases: every term counts
        prm.data.normal_(0, 0.3)
    rng = np.random.default_rng(0)
    mean = rng.normal(size=IN_CHANNELS - 1).astype(np.float32)
    std = rng.uniform(0.5, 2, IN_CHANNELS - 1).astype(np.float32)
    proj = rng.normal(size=(IN_CHANNELS - 1, p)).astype(np.float32) / 10
    params = {k: v.detach().numpy() for k, v in model.state_dict().items()}
    path = save_weights(
        tmp_path / "w.npz", {**params, "mean": mean, "std": std, "proj": proj}, {"feature_width": 64}
    )
    x = rng.normal(size=(11, 13, IN_CHANNELS)).astype(np.float32)
    got = AnimalNet(path).logits(x)
    a = ((x[..., :-1] - mean) / std) @ proj
    t = torch.as_tensor(np.concatenate([a, x[..., -1:]], -1)).permute(2, 0, 1)[None]
    want = model(t)[0, 0].detach().numpy()
    assert got.shape == (11, 13)
    np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-4)


def test_bad_weights_are_one_clear_error(tmp_path, monkeypatch):
    from zooctl.video.animalnet import AnimalNet

    monkeypatch.setenv("ZOOCTL_ANIMALNET_WEIGHTS", str(tmp_path / "none.npz"))
    with pytest.raises(InputError, match="do not exist"):
        AnimalNet()
    bad = tmp_path / "bad.npz"
    np.savez(bad, info=np.array("{}"), x=np.zeros(2))
    with pytest.raises(InputError, match="not an animalnet weights file"):
        AnimalNet(bad)
    from zooctl.pipelines.segment_train import _model, save_weights
    from zooctl.video.animalnet import IN_CHANNELS

    params = {k: v.detach().numpy() for k, v in _model(9).state_dict().items()}
    ok = {"mean": np.zeros(IN_CHANNELS - 1), "std": np.ones(IN_CHANNELS - 1)}
    wrong = save_weights(tmp_path / "w.npz", {**params, **ok, "proj": np.zeros((IN_CHANNELS - 1, 4))}, {})
    with pytest.raises(InputError, match="shapes differ"):
        AnimalNet(wrong)


@pytest.fixture(scope="module")
def trained(tmp_path_factory, animals):
    """Weights from a small training run (its numbers mean nothing; that it runs and learns does)."""
    from zooctl.pipelines.segment_train import SegmentTrainConfig, train

    out = tmp_path_factory.mktemp("animalnet") / "w.npz"
    cfg = SegmentTrainConfig(samples=12, steps=30, batch=4, size=(96, 64), components=8, crop=(6, 8))
    seen = []
    info = train(animals, out, cfg, {"licence": "test"}, lambda s, i, n: seen.append(s))
    return out, info, seen


def test_training_runs_end_to_end_and_learns(trained):
    out, info, seen = trained
    assert out.is_file() and {"composites", "training"} <= set(seen)
    r = info["report"]
    assert r["loss_last"] < r["loss_first"]
    assert info["sources"] == {"licence": "test"} and info["config"]["samples"] == 12


def test_segmenter_through_the_hook_keeps_a_tracked_animal(trained):
    frames, truth = moving_object_video(t=6, h=72, w=96)
    # a network trained this briefly knows nothing: at weight 0 the tracker's masks stand
    seg = get_registry().get("segmenter", "animalnet").create(weights=str(trained[0]), net_weight=0.0)
    masks = np.asarray(seg.segment(frames), bool)
    assert masks.shape == truth.shape
    assert np.mean([iou(m, t) for m, t in zip(masks, truth)]) > 0.6
    assert "animalnet" in seg.report and seg.report["animalnet"]["weights"] == str(trained[0])
    # the network's evidence decides against a weak tracker prior
    ev = np.full((72, 96), -5.0, np.float32)
    ev[20:40, 30:60] = 5.0
    tracked = np.zeros((72, 96), bool)
    tracked[50:70, 0:20] = True
    seg.net_weight, seg.prior_weight, seg.erase = 1.0, 1.0, True
    got = seg.decide(ev, tracked)
    assert got[30, 45] and not got[60, 10]
    # by default the network only adds: its "no" does not erase a tracked animal it cannot see
    seg.erase = False
    ev[:] = -5.0
    got = seg.decide(ev, tracked)
    assert got[60, 10] and not got[30, 45]
    seg.erase = True
    assert not seg.decide(ev, tracked).any()


def test_cli_trains_and_refuses_bad_input(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("ZOOCTL_STORE", str(tmp_path / "store"))
    r = run_inprocess(capsys, "segment", "train", "--samples", "3")
    assert r.code != 0 and "--samples >= 10" in r.err and "Traceback" not in r.err
    r = run_inprocess(capsys, "segment", "train", "--procedural", "0", "--samples", "10")
    assert r.code != 0 and "nothing to train on" in r.err


def test_cli_trains_weights_the_segmenter_loads(tmp_path, capsys, monkeypatch):
    from zooctl.video.animalnet import AnimalNet

    monkeypatch.setenv("ZOOCTL_STORE", str(tmp_path / "store"))
    args = ("segment", "train", "--samples", "10", "--steps", "3", "--procedural", "2", "--no-bank", "--json")
    r = run_inprocess(capsys, *args)
    assert r.code == 0, r.err
    import json

    res = json.loads(r.out)
    path = tmp_path / "store" / "models" / "animalnet.npz"
    assert res["weights"] == str(path) and path.is_file()
    assert res["sources"]["procedural_animals"] == 2 and res["sources"]["bank_assets"] == []
    assert AnimalNet(path).info["config"]["steps"] == 3


def test_weights_come_from_the_store_named_else_the_shipped_ones(tmp_path, capsys, monkeypatch):
    from zooctl.paths import use_store
    from zooctl.video.animalnet import SHIPPED_WEIGHTS, AnimalNet, weights_file

    monkeypatch.delenv("ZOOCTL_ANIMALNET_WEIGHTS", raising=False)
    monkeypatch.setenv("ZOOCTL_STORE", str(tmp_path / "empty"))
    assert weights_file() == SHIPPED_WEIGHTS
    info = AnimalNet().info  # the shipped weights say what they were made from
    assert info["sources"]["bank_assets"] == [] and "no video frames" in info["sources"]["scenes"]
    # `segment train` into the store named by --store: that store's weights are used from then on
    other = tmp_path / "other"
    args = ("--store", str(other), "segment", "train", "--samples", "10", "--steps", "2", "--procedural", "2")
    assert run_inprocess(capsys, *args, "--no-bank", "--json").code == 0
    use_store(other)
    assert weights_file() == other / "models" / "animalnet.npz"


def test_motion_contrast_tells_a_moving_region_from_the_still_ground():
    from zooctl.video.animalnet import motion_contrast

    residual = np.zeros((60, 80), np.float32)
    residual[20:40, 30:50] = 3.0  # a region moving against the camera
    moving = np.zeros((60, 80), bool)
    moving[20:40, 30:50] = True
    still = np.zeros((60, 80), bool)
    still[5:15, 5:25] = True
    assert motion_contrast(moving, residual) == pytest.approx(3.0)
    assert motion_contrast(still, residual) == pytest.approx(0.0)
    assert motion_contrast(np.zeros((60, 80), bool), residual) == 0.0  # no region, no claim


def test_a_tracker_lost_on_the_ground_gives_way_to_the_animal_the_network_sees_moving(animals):
    """With the shipped weights, on synthetic composites (camera panning, the animal moving): masks
    held on a patch of still ground are replaced by the network's animal where it finds one, and masks
    on the animal itself are never replaced."""
    from zooctl.benchdata.composites import composite
    from zooctl.video.animalnet import AnimalNetSegmenter
    from zooctl.video.flow import DISFlow, compute_video_flow

    seg = AnimalNetSegmenter(relabel=False)
    replaced, found = [], []
    for seed in range(6):
        s = composite(animals, np.random.default_rng(seed), (320, 240))
        flow = compute_video_flow(DISFlow("medium"), s.frames)
        truth = np.stack([s.mask, s.mask])
        seg.decide_video(s.frames, truth, flow)
        assert not seg.report["animalnet"]["network_replaced_tracker"], seed
        lost = np.zeros_like(truth)
        lost[:, 10:60, 10:80] = True
        lost &= ~truth
        got = np.asarray(seg.decide_video(s.frames, lost, flow, seed_frame=0), bool)
        if seg.report["animalnet"]["network_replaced_tracker"]:
            assert not seg.report["animalnet"]["identity_kept_tracker"], seed
            replaced.append(seed)
            found.append(iou(got[0], s.mask))
    assert len(replaced) >= 2 and min(found) > 0.5, (replaced, found)


def test_the_network_part_that_is_the_tracked_animal_is_followed_and_a_second_one_is_not():
    """A second animal only touches the tracked one: it is not the same part; the part overlapping
    the tracked mask is, and it is followed from frame to frame while another part moves apart."""
    from zooctl.video.animalnet import animal_parts, follow_part, same_part

    ev = np.full((4, 60, 80), -5.0, np.float32)
    for i in range(4):
        ev[i, 20:40, 10 + 3 * i : 25 + 3 * i] = 5.0  # the animal, moving right
        ev[i, 5:15, 70 - 5 * i : 78 - 5 * i] = 5.0  # a second one, moving left
    held = np.zeros((60, 80), bool)
    held[20:40, 25:35] = True  # touches the animal's right side on frame 0: one column shared
    assert same_part(animal_parts(ev[0])[0], held) is None
    held[20:40, 15:35] = True  # now overlaps half of it
    label = same_part(animal_parts(ev[0])[0], held)
    assert label is not None
    got = dict(follow_part(lambda i: ev[i], [0, 1, 2, 3], 0, label))
    for i in range(4):
        assert (got[i] == (ev[i] > 0) & (np.arange(60)[:, None] >= 20)).all(), i
    ev[2] = -5.0  # the network loses it on frame 2: nothing there, found again on frame 3
    got = dict(follow_part(lambda i: ev[i], [0, 1, 2, 3], 0, label))
    assert got[2] is None and got[3][30, 25 + 3 * 3 - 10]


def test_remnants_far_smaller_than_the_animal_are_dropped_unless_cut_by_the_edge():
    from zooctl.video.animalnet import drop_remnants

    masks = np.zeros((6, 60, 80), bool)
    masks[:3, 10:50, 10:60] = True  # the animal: 2,000 pixels
    masks[3, 30:34, 30:34] = True  # a speck left on the ground (16)
    masks[4, 20:40, 0:4] = True  # the animal entering at the edge (80)
    before = masks.copy()
    assert drop_remnants(masks, 0.0) == [] and (masks == before).all()
    assert drop_remnants(masks, 0.1) == [3]
    assert not masks[3].any() and (masks[4] == before[4]).all() and (masks[:3] == before[:3]).all()
    assert drop_remnants(np.zeros((3, 8, 8), bool), 0.1) == []  # nothing seen: nothing to judge


def test_a_small_animal_is_decided_on_the_part_of_the_frame_it_keeps_to(animals):
    """An animal kept to a small part of a large frame is decided on that part, enlarged; a large
    one on the whole frame; the masks come back at the frame's size and keep the animal."""
    from zooctl.benchdata.composites import composite
    from zooctl.video.animalnet import AnimalNetSegmenter, _kept_to
    from zooctl.video.flow import DISFlow, compute_video_flow

    big = np.zeros((2, 60, 80), bool)
    big[:, 5:50, 10:70] = True
    assert _kept_to(big, 80, 60) is None
    assert _kept_to(np.zeros((2, 60, 80), bool), 80, 60) is None
    small = np.zeros((2, 60, 80), bool)
    small[0, 10:20, 10:20] = True
    small[1, 12:22, 14:24] = True
    assert _kept_to(small, 80, 60) == (
        6,
        7,
        22,
        18,
    )  # both frames' masks (14 x 12), a quarter wider each side

    s = composite(animals, np.random.default_rng(0), (320, 240))
    frames = np.full((2, 600, 800, 3), 128, np.uint8)
    frames[:, 300:540, 400:720] = s.frames
    truth = np.zeros((2, 600, 800), bool)
    truth[:, 300:540, 400:720] = s.mask
    flow = compute_video_flow(DISFlow("medium"), frames)
    seg = AnimalNetSegmenter()
    got = np.asarray(seg.decide_near(frames, truth, flow, seed_frame=0), bool)
    assert got.shape == truth.shape and seg.report["animalnet"]["crop"] is not None
    assert iou(got[0], truth[0]) > 0.6
    # a long video's arrays wait in scratch files: the same masks from them
    from zooctl.video.flow import VideoFlow
    from zooctl.video.scratch import ScratchArray

    def lazy(a):
        out = ScratchArray(len(a), a.shape[1:], a.dtype)
        for i, x in enumerate(a):
            out[i] = x
        return out

    lazy_flow = VideoFlow(lazy(flow.forward), lazy(flow.backward), None, None)
    again = seg.decide_near(lazy(frames), lazy(truth), lazy_flow, seed_frame=0)
    assert (np.stack(list(again)) == got).all()
    whole = np.zeros((2, 240, 320), bool)
    whole[:, 20:220, 20:300] = True  # a tracked animal over most of the frame: no crop
    seg.decide_near(s.frames, whole, compute_video_flow(DISFlow("medium"), s.frames))
    assert seg.report["animalnet"]["crop"] is None


def test_video_show_says_whether_the_network_replaced_the_tracker():
    from zooctl.video.stats import seeding_lines

    replaced = {
        "seeding": ["network"] * 4,
        "seed_frame": 2,
        "animalnet": {"motion_margin": 0.98, "network_replaced_tracker": True},
        "self_training": {"changed": 0.24},
    }
    text = "\n".join(seeding_lines(replaced))
    assert "seeding: 4 network" in text and "first seed" not in text
    assert "+0.98% of the width" in text and "replaced the tracker's masks" in text
    assert "24.0% of mask pixels changed" in text
    other = {
        "seeding": ["localiser", "tracked", "empty"],
        "seed_frame": 0,
        "animalnet": {
            "motion_margin": 1.13,
            "network_replaced_tracker": False,
            "identity_kept_tracker": True,
            "remnants_dropped": [2],
            "crop": [10, 20, 200, 120],
        },
    }
    text = "\n".join(seeding_lines(other))
    assert "the animal moving most was not the tracked one" in text and "frames 2" in text
    assert "200x120 at (10, 20)" in text
    kept = {"seeding": ["localiser", "tracked"], "seed_frame": 0, "animalnet": {"motion_margin": None}}
    text = "\n".join(seeding_lines(kept))
    assert "first seed on frame 0" in text and "saw no animal: the tracker's masks kept" in text
    assert "covers" not in text
    piece = {
        "seeding": ["network"] * 3,
        "animalnet": {
            "motion_margin": -0.08,
            "network_replaced_tracker": True,
            "part_cover": 3.632,
            "replaced_as_part": True,
        },
    }
    text = "\n".join(seeding_lines(piece))
    assert "covers 3.63 times its area: the tracker held a piece of the animal" in text
    piece["animalnet"].update(part_cover=0.9, replaced_as_part=False, network_replaced_tracker=False)
    text = "\n".join(seeding_lines(piece))
    assert "covers 0.90 times its area" in text and "held a piece" not in text
    piece.update(seeds_tried={"10": 0.2065, "0": 0.2668}, seed_frame=0)
    text = "\n".join(seeding_lines(piece))
    assert "seed frames tried (agreement with the network): 10 (0.21), 0 (0.27); kept 0" in text


def test_the_tracker_the_networks_looks_and_the_relabelling_share_each_frames_motion_residual(
    trained, monkeypatch
):
    from zooctl.video import cues
    from zooctl.video import flow as flow_mod

    frames, truth = moving_object_video(t=6, h=72, w=96)
    made = []

    def counted(motion):
        made.append(1)
        return cues.background_motion_residual(motion)

    monkeypatch.setattr(flow_mod, "background_motion_residual", counted)
    seg = get_registry().get("segmenter", "animalnet").create(weights=str(trained[0]))
    assert seg.relabel and seg.relabel_options.get("motion_weight")  # all three ask for them
    masks = np.asarray(seg.segment(frames), bool)
    assert masks.shape == truth.shape
    assert len(made) == len(frames)  # was up to three times a frame


def test_the_part_that_holds_a_tracked_piece_and_how_much_more_it_covers():
    """A tracked piece inside the network's animal, or over its outline by less than a cell of the
    network's grid, is held by it; a region off the animal is not; the cover is the parts' summed
    area over the tracked masks', and no cover is claimed for masks the parts do not hold."""
    from zooctl.video.animalnet import animal_parts, follow_part, holding_part, part_cover

    ev = np.full((3, 120, 160), -5.0, np.float32)
    for i in range(3):
        ev[i, 40:80, 20 + 4 * i : 100 + 4 * i] = 5.0  # the animal, 40 x 80, moving right
        ev[i, 5:15, 130:150] = 5.0  # something else, far from it
    labels = animal_parts(ev[0])[0]
    piece = np.zeros((3, 120, 160), bool)
    for i in range(3):
        piece[i, 50:60, 90 + 4 * i : 104 + 4 * i] = True  # the tail: 4 of its 14 columns over the outline
    label = holding_part(labels, piece[0])
    assert label is not None and labels[60, 50] == label
    off = np.zeros((120, 160), bool)
    off[90:110, 20:60] = True  # the ground under the animal
    assert holding_part(labels, off) is None
    assert holding_part(labels, np.zeros((120, 160), bool)) is None
    got = part_cover(follow_part(lambda i: ev[i], [0, 1, 2], 0, label), piece)
    assert got == pytest.approx(3 * 40 * 80 / (3 * 10 * 14))
    whole = np.zeros((3, 120, 160), bool)
    for i in range(3):
        whole[i] = ev[i] > 0
        whole[i, :20] = False
    assert part_cover(follow_part(lambda i: ev[i], [0, 1, 2], 0, label), whole) == pytest.approx(1.0)
    strayed = piece.copy()
    strayed[1:] = False
    strayed[1:, 90:110, 20:60] = True  # the tracker slid onto the ground after the first frame
    assert part_cover(follow_part(lambda i: ev[i], [0, 1, 2], 0, label), strayed) is None


def test_a_tracker_holding_a_piece_of_the_animal_gives_way_to_the_network_part_that_holds_it(animals):
    """With the shipped weights, on synthetic composites: masks held on a small piece of the animal
    are replaced by the network's part of it (and not decided on a crop around the piece) where the
    network finds the animal, masks of the whole animal never are, and with the gate shut
    (``switch_cover`` < 0) the piece stands."""
    from zooctl.benchdata.composites import composite
    from zooctl.video.animalnet import AnimalNetSegmenter
    from zooctl.video.flow import DISFlow, compute_video_flow

    seg = AnimalNetSegmenter(relabel=False, switch_cover=2.0)
    shut = AnimalNetSegmenter(relabel=False, switch_cover=-1.0)
    found = []
    for seed in range(6):
        s = composite(animals, np.random.default_rng(seed), (320, 240))
        flow = compute_video_flow(DISFlow("medium"), s.frames)
        truth = np.stack([s.mask, s.mask])
        seg.decide_near(s.frames, truth, flow, seed_frame=0)
        assert not seg.report["animalnet"]["replaced_as_part"], seed
        ys, xs = np.nonzero(s.mask)
        y, x = int(np.median(ys)), int(np.median(xs))
        r = max(int(np.sqrt(len(ys)) / 6), 2)  # a square about a ninth of the animal's area
        piece = np.zeros_like(truth)
        piece[:, y - r : y + r, x - r : x + r] = True
        piece &= truth
        got = np.asarray(seg.decide_near(s.frames, piece, flow, seed_frame=0), bool)
        if seg.report["animalnet"]["replaced_as_part"]:
            assert seg.report["animalnet"]["part_cover"] > 2.0 and seg.report["animalnet"]["crop"] is None
            found.append(iou(got[0], s.mask) / iou(piece[0], s.mask))
            kept = np.asarray(shut.decide_near(s.frames, piece, flow, seed_frame=0), bool)
            assert not shut.report["animalnet"]["replaced_as_part"] and (kept == piece).all()
    assert len(found) >= 2 and min(found) > 3.0, found  # the animal, not the piece


def test_network_agreement_is_the_mean_iou_with_the_network_animal_over_the_looked_frames():
    from zooctl.video.animalnet import network_agreement

    logit = np.full((2, 10, 10), -3.0, np.float32)
    logit[0, :5] = 3.0  # 50 cells
    masks = np.zeros((3, 10, 10), bool)
    masks[0, :5, :5] = True  # 25 of them
    looks = {0: (logit[0], None, None), 2: (logit[1], None, None)}  # frame 2: nothing either way
    assert network_agreement(masks, looks) == pytest.approx((0.5 + 1.0) / 2)
    assert network_agreement(masks, {}) == 0.0


def test_other_seed_frames_are_tried_and_the_masks_the_network_agrees_with_most_kept(monkeypatch):
    """``seeds``: the tracker is started again from its next-ranked keyframes (``start_at``) and the
    segmentation whose masks agree most with the network's animal is kept; never joining the first
    pass, it is exactly the segmentation started from that frame. One seed: the tracker's own
    choice, nothing tried."""
    from zooctl.video import grabcut
    from zooctl.video.animalnet import AnimalNetSegmenter

    monkeypatch.setattr(grabcut, "JOIN_IOU", 2.0)

    frames, truth = moving_object_video(t=21, h=96, w=128)
    one = AnimalNetSegmenter(snap=False, seeds=1)
    first = np.asarray(one.segment(frames), bool)
    ranking = one.report["seed_ranking"]
    assert "seeds_tried" not in one.report and ranking and ranking[0] == one.report["seed_frame"]

    seg = AnimalNetSegmenter(snap=False, seeds=3, seeds_margin=-1.0)  # any other seed's lead counts
    got = np.asarray(seg.segment(frames), bool)
    tried = seg.report["seeds_tried"]
    assert list(tried) == ranking[: len(tried)] and len(tried) == min(3, len(ranking)) >= 2
    chosen = seg.report["seed_frame"]
    assert tried[chosen] == max(tried.values())
    assert chosen == next(k for k in tried if tried[k] == max(tried.values()))  # the first on a tie
    # another seed leaves the first only by a clear lead: past any possible lead, the first stays
    sure = AnimalNetSegmenter(snap=False, seeds=3, seeds_margin=1.0)
    assert (np.asarray(sure.segment(frames), bool) == first).all()
    assert sure.report["seed_frame"] == ranking[0] and sure.report["seeds_tried"] == tried
    again = AnimalNetSegmenter(snap=False, seeds=1)
    again.tracker.start_at = chosen
    assert (np.asarray(again.segment(frames), bool) == got).all()
    assert again.report["seed_frame"] == chosen
    if chosen == ranking[0]:
        assert (got == first).all()
    assert np.mean([iou(m, t) for m, t in zip(got, truth)]) > 0.5


def test_another_seeds_pass_joins_the_first_where_it_finds_the_same_animal(monkeypatch):
    """A pass from another seed whose mask on a frame overlaps the first pass's by `JOIN_IOU` takes
    the first pass's masks for the rest of that direction: fewer frames tracked, the masks as
    without joining but for what the copied frames would have drifted."""
    from zooctl.video import grabcut
    from zooctl.video.animalnet import AnimalNetSegmenter

    frames, _ = moving_object_video(t=21, h=120, w=160, seed=1)  # every seed finds the ellipse
    cuts: list[int] = []
    track = grabcut.GrabCutTracker._track
    monkeypatch.setattr(grabcut.GrabCutTracker, "_track", lambda self, *a: cuts.append(1) or track(self, *a))
    runs = {}
    for join in (2.0, grabcut.JOIN_IOU):
        monkeypatch.setattr(grabcut, "JOIN_IOU", join)
        cuts.clear()
        seg = AnimalNetSegmenter(snap=False, relabel=False, seeds=3, seeds_margin=-1.0)
        runs[join] = (np.asarray(seg.segment(frames), bool), len(cuts), seg.report["seeds_tried"])
    (never, n_never, tried_never), (joined, n_joined, tried_joined) = runs.values()
    assert list(tried_never) == list(tried_joined) and len(tried_joined) >= 2
    assert n_joined < n_never
    assert np.mean([iou(a, b) for a, b in zip(joined, never)]) > 0.9


def test_other_seeds_reuse_the_first_passs_looks(monkeypatch):
    """The passes from the other seeds take the localiser's looks of the first pass (the same
    frames): the classifier runs on about as many frames with ``seeds=3`` as with one seed."""
    from zooctl.video.animalnet import AnimalNetSegmenter
    from zooctl.video.localise import Localiser

    frames, _ = moving_object_video(t=21, h=96, w=128)
    looked: list[int] = []
    evidence = Localiser.evidence
    monkeypatch.setattr(Localiser, "evidence", lambda self, frame: looked.append(1) or evidence(self, frame))
    AnimalNetSegmenter(snap=False, seeds=1).segment(frames)
    one = len(looked)
    seg = AnimalNetSegmenter(snap=False, seeds=3, seeds_margin=-1.0)
    seg.segment(frames)
    assert len(seg.report["seeds_tried"]) >= 2 and 0 < len(looked) - one <= 1.5 * one  # not 3 times


def test_a_segmenter_option_of_the_wrong_kind_is_one_clear_line(store, tmp_path, capsys):
    """A number or true/false option given something else fails at once with what it takes, for the
    segmenter's own options and those it forwards to its tracker; nothing is stored."""
    from video_helpers import write_pngs

    frames, _ = moving_object_video(t=4, h=48, w=64)
    folder = write_pngs(tmp_path / "clip", frames)
    for option, said in (
        ("seeds=abc", "seeds='abc' is not a whole number"),
        ("seeds=2.5", "seeds=2.5 is not a whole number"),
        ("switch_cover=x", "switch_cover='x' is not a number"),
        ("snap=maybe", "snap='maybe' is not true or false"),
        ("key_every=often", "key_every='often' is not a whole number"),  # the tracker's
    ):
        r = run_inprocess(capsys, "video", "add", str(folder), "--seg-option", option, "-q")
        assert r.code == 2 and said in r.err and "Traceback" not in r.err, (option, r.err)
    r = run_inprocess(capsys, "video", "list")
    assert r.code == 0 and "clip" not in r.out


def test_with_flip_the_networks_look_at_a_mirrored_frame_is_its_look_mirrored(animals):
    from zooctl.benchdata.composites import composite

    s = composite(animals, np.random.default_rng(4), (128, 96))
    frame, residual = s.frames[0], np.abs(np.random.default_rng(0).normal(size=(96, 128))).astype(np.float32)
    mirror, mirrored_residual = (np.ascontiguousarray(a[:, ::-1]) for a in (frame, residual))
    seg = get_registry().get("segmenter", "animalnet").create(flip=True)
    assert seg.tracker.flip  # the tracker's localiser looks both ways too
    a, b = seg.look(frame, residual)[0], seg.look(mirror, mirrored_residual)[0]
    assert np.abs(a - b[:, ::-1]).max() < 1e-4 * max(1.0, float(np.abs(a).max()))
    plain = get_registry().get("segmenter", "animalnet").create()
    p, q = plain.look(frame, residual)[0], plain.look(mirror, mirrored_residual)[0]
    assert np.abs(p - q[:, ::-1]).max() > 1e-2  # one look alone differs (what the option is for)
    assert np.abs(a - p).max() > 1e-3
