"""J (DAVIS region similarity) and choosing a setting leave-one-video-out, on synthetic masks."""

from __future__ import annotations

import numpy as np
import pytest

from zooctl.video.mask_quality import best_setting, frame_j, leave_one_out, per_frame_j


def _square(x0, y0, x1, y1, shape=(20, 30)):
    m = np.zeros(shape, bool)
    m[y0:y1, x0:x1] = True
    return m


def test_frame_j_is_intersection_over_union():
    a = _square(0, 0, 10, 10)  # 100 px
    b = _square(5, 0, 15, 10)  # 100 px, 50 shared
    assert frame_j(a, b) == pytest.approx(50 / 150)
    assert frame_j(a, a) == 1.0
    assert frame_j(a, _square(20, 10, 30, 20)) == 0.0


def test_both_empty_counts_one_and_one_empty_counts_zero():
    empty = np.zeros((20, 30), bool)
    assert frame_j(empty, empty) == 1.0  # animal absent and nothing masked
    assert frame_j(empty, _square(0, 0, 3, 3)) == 0.0  # missed it
    assert frame_j(_square(0, 0, 3, 3), empty) == 0.0  # masked something that is not there


def test_per_frame_j_and_its_checks():
    truth = np.stack([_square(0, 0, 10, 10), np.zeros((20, 30), bool), _square(0, 0, 10, 10)])
    masks = np.stack([_square(0, 0, 10, 5), np.zeros((20, 30), bool), np.zeros((20, 30), bool)])
    np.testing.assert_allclose(per_frame_j(masks, truth), [0.5, 1.0, 0.0])
    with pytest.raises(ValueError, match="3 ground-truth frames"):
        per_frame_j(masks[:2], truth)
    with pytest.raises(ValueError, match="shape"):
        frame_j(np.zeros((4, 4), bool), np.zeros((4, 5), bool))


def test_leave_one_out_picks_on_the_others_and_reports_the_held_out_video():
    # setting 2 is much better on v1 alone; 1 is a little better on every other video
    scores = {
        1: {"v1": 0.30, "v2": 0.80, "v3": 0.70, "v4": 0.60},
        2: {"v1": 0.90, "v2": 0.75, "v3": 0.66, "v4": 0.58},
        3: {"v1": 0.20, "v2": 0.50, "v3": 0.50, "v4": 0.50},
    }
    r = leave_one_out(scores, prefer=1)
    # in-sample, 2 wins on the mean (0.7225 against 0.60): v1's own gain buys it
    assert r.best == 2
    assert r.in_sample == scores[2]
    # held out, v1 does not see its own gain: 1 is picked on v2-v4, and v1 scores 0.30 at it
    assert r.picked == {"v1": 1, "v2": 2, "v3": 2, "v4": 2}
    assert r.held_out == {"v1": 0.30, "v2": 0.75, "v3": 0.66, "v4": 0.58}
    assert r.held_out_mean == pytest.approx((0.30 + 0.75 + 0.66 + 0.58) / 4)
    assert r.in_sample_mean == pytest.approx((0.90 + 0.75 + 0.66 + 0.58) / 4)
    assert r.held_out_mean < r.in_sample_mean  # the in-sample number flatters the setting


def test_ties_keep_the_default_else_the_first_listed():
    scores = {"a": {"x": 0.5, "y": 0.7}, "b": {"x": 0.7, "y": 0.5}, "c": {"x": 0.6, "y": 0.6}}
    assert best_setting(scores, ["x", "y"], prefer="c") == "c"
    assert best_setting(scores, ["x", "y"]) == "a"
    assert best_setting(scores, ["x"], prefer="c") == "b"


def test_leave_one_out_refuses_what_it_cannot_judge():
    with pytest.raises(ValueError, match="at least two"):
        leave_one_out({1: {"v": 0.5}, 2: {"v": 0.6}})
    with pytest.raises(ValueError, match="other videos"):
        leave_one_out({1: {"v": 0.5, "w": 0.5}, 2: {"v": 0.6}})
    with pytest.raises(ValueError, match="no settings"):
        leave_one_out({})
