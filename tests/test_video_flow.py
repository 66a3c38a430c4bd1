"""DIS flow, warping and the forward-backward occlusion check on frames with known motion."""

from __future__ import annotations

import numpy as np
import pytest
from video_helpers import texture

from zooctl.errors import UsageError
from zooctl.plugins import get_registry
from zooctl.video.flow import DISFlow, compute_video_flow, fb_inconsistent, flow_to_rgb, warp


def shifted_pair(dx: int, dy: int, h: int = 96, w: int = 128):
    big = texture(h + 20, w + 20, seed=3)
    a = big[10 : 10 + h, 10 : 10 + w]
    b = big[10 - dy : 10 - dy + h, 10 - dx : 10 - dx + w]  # content moves by (+dx, +dy) from a to b
    return np.ascontiguousarray(a), np.ascontiguousarray(b)


def test_dis_recovers_a_translation():
    a, b = shifted_pair(3, -2)
    flow = get_registry().get("flow_estimator", "dis").create(preset="medium").flow(a, b)
    assert flow.shape == (96, 128, 2) and flow.dtype == np.float32
    inner = flow[16:-16, 16:-16].reshape(-1, 2)
    assert np.median(inner, 0) == pytest.approx([3, -2], abs=0.25)


def test_dis_at_a_smaller_working_size_returns_full_size_flow():
    a, b = shifted_pair(6, -4, h=192, w=256)
    flow = DISFlow("medium", max_size=128).flow(a, b)  # computed at 128x96, displacements rescaled
    assert flow.shape == (192, 256, 2) and flow.dtype == np.float32
    assert np.median(flow[32:-32, 32:-32].reshape(-1, 2), 0) == pytest.approx([6, -4], abs=0.5)
    with pytest.raises(UsageError):
        DISFlow(max_size=4)
    assert DISFlow(max_size=0).max_size is None  # 0: full size


def test_warp_with_backward_flow_reconstructs_the_first_frame():
    a, b = shifted_pair(4, 0)
    back = DISFlow().flow(b, a)  # b -> a: sampling a at x + back(x) gives b
    rec = warp(a.astype(np.float32), back)
    err = np.abs(rec - b.astype(np.float32))[16:-16, 16:-16].mean()
    assert err < 6


def test_video_flow_and_occlusion_masks():
    a, b = shifted_pair(5, 0)
    frames = np.stack([a, b, a])
    vf = compute_video_flow(DISFlow("fast"), frames)
    assert vf.forward.shape == (2, 96, 128, 2) and vf.occlusion_forward.shape == (2, 96, 128)
    assert np.median(vf.forward[0][:, 20:-20, 0]) == pytest.approx(5, abs=0.5)
    assert np.median(vf.backward[0][:, 20:-20, 0]) == pytest.approx(-5, abs=0.5)
    # pixels that leave the frame (right edge moving right) fail the check; the middle passes
    assert vf.occlusion_forward[0][:, -3:].mean() > 0.9
    assert vf.occlusion_forward[0][:, 20:-20].mean() < 0.1


def test_fb_check_flags_inconsistent_flow():
    f = np.zeros((32, 32, 2), np.float32)
    f[..., 0] = 2
    assert not fb_inconsistent(f, -f)[:, :-4].any()
    assert fb_inconsistent(f, f)[:, :-4].all()  # going there and "back" by the same vector


def test_flow_colours_and_bad_preset():
    f = np.zeros((8, 8, 2), np.float32)
    f[:, :4, 0] = 3
    rgb = flow_to_rgb(f)
    assert rgb.shape == (8, 8, 3) and rgb.dtype == np.uint8
    assert (rgb[:, 4:] == 255).all() and not (rgb[:, :4] == 255).all()  # still is white, motion has colour
    with pytest.raises(UsageError, match="unknown DIS preset"):
        DISFlow("slowest")


def test_threaded_video_flow_equals_one_thread():
    frames = np.stack([shifted_pair(k, k // 2)[1] for k in range(5)])
    one = compute_video_flow(DISFlow("fast"), frames, workers=1)
    done = []
    two = compute_video_flow(DISFlow("fast"), frames, workers=2, progress=lambda d, t: done.append((d, t)))
    for key in ("forward", "backward", "occlusion_forward", "occlusion_backward"):
        assert np.array_equal(getattr(one, key), getattr(two, key)), key
    assert done == [(1, 4), (2, 4), (3, 4), (4, 4)]


def test_an_estimator_not_marked_thread_safe_runs_on_one_thread():
    import threading

    class Shift:  # a plug-in estimator without ``thread_safe``: called from one thread only
        def __init__(self):
            self.threads = set()

        def flow(self, a, b):
            self.threads.add(threading.get_ident())
            f = np.zeros(a.shape[:2] + (2,), np.float32)
            f[..., 0] = 1.0
            return f

    est = Shift()
    vf = compute_video_flow(est, np.zeros((4, 16, 16, 3), np.uint8), workers=2)
    assert len(est.threads) == 1 and (vf.forward[..., 0] == 1).all()


def test_fb_check_matches_its_formula():
    rng = np.random.default_rng(0)
    f = rng.normal(0, 2, (24, 40, 2)).astype(np.float32)
    b = rng.normal(0, 2, (24, 40, 2)).astype(np.float32)
    back = warp(b, f)
    lhs = ((f + back) ** 2).sum(-1)
    rhs = 0.01 * ((f**2).sum(-1) + (back**2).sum(-1)) + 0.5
    gy, gx = np.mgrid[0:24, 0:40]
    x, y = gx + f[..., 0], gy + f[..., 1]
    expect = (lhs > rhs) | (x < 0) | (x > 39) | (y < 0) | (y > 23)
    got = fb_inconsistent(f, b)
    assert got.dtype == bool and np.mean(got == expect) > 0.999  # float rounding at the threshold


def _two_motions(t: int = 4):
    from video_helpers import moving_object_video

    frames, _ = moving_object_video(t=t, h=72, w=96)
    return compute_video_flow(DISFlow("medium"), frames)


def test_each_frames_motion_residual_is_that_of_its_own_flow_made_once_for_every_thread(monkeypatch):
    import threading

    from zooctl.video import cues
    from zooctl.video import flow as flow_mod

    vf = _two_motions()
    expected = [cues.background_motion_residual(vf.forward[i]) for i in range(3)]
    expected.append(cues.background_motion_residual(-vf.backward[2]))  # the last frame: backward, reversed
    assert np.array_equal(vf.motion(3), -vf.backward[2]) and np.array_equal(vf.motion(0), vf.forward[0])
    made, gate = [], threading.Barrier(4)

    def counted(motion):
        made.append(1)
        return cues.background_motion_residual(motion)

    monkeypatch.setattr(flow_mod, "background_motion_residual", counted)

    def ask():
        gate.wait()  # four threads ask for every frame at once
        return [vf.residual(i) for i in (3, 0, 1, 2, -1)]

    got = [[] for _ in range(4)]
    threads = [threading.Thread(target=lambda k=k: got[k].extend(ask())) for k in range(4)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert len(made) == 4  # one residual a frame, whoever asked first made it
    for seen in got:
        assert [np.array_equal(a, expected[i]) for a, i in zip(seen, (3, 0, 1, 2, 3))] == [True] * 5
    with pytest.raises(ValueError):
        vf.residual(0)[0, 0] = 1.0  # shared between its readers: read-only


def test_a_residual_whose_maker_failed_is_made_by_the_next_caller(monkeypatch):
    from zooctl.video import cues
    from zooctl.video import flow as flow_mod
    from zooctl.video.flow import VideoFlow
    from zooctl.video.scratch import ScratchArray

    vf = _two_motions(3)
    lazy = VideoFlow(*(ScratchArray(2, a.shape[1:], a.dtype) for a in (vf.forward, vf.backward)), None, None)
    for i in range(2):
        lazy.forward[i], lazy.backward[i] = vf.forward[i], vf.backward[i]

    def failing(motion):
        raise MemoryError("out of memory")

    monkeypatch.setattr(flow_mod, "background_motion_residual", failing)
    with pytest.raises(MemoryError):
        lazy.residual(1)
    monkeypatch.setattr(flow_mod, "background_motion_residual", cues.background_motion_residual)
    # a long video's residuals wait in a scratch file, as its flow does
    assert np.array_equal(lazy.residual(1), cues.background_motion_residual(vf.forward[1]))
    assert np.array_equal(lazy.residual(2), cues.background_motion_residual(-vf.backward[1]))
