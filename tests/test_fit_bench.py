"""`bench make` ground truth and `bench run`'s table, on a tiny tube video."""

from __future__ import annotations

import json

import numpy as np
import pytest
from fit_helpers import tiny_overrides
from PIL import Image

from zooctl.benchdata.make import make_video
from zooctl.benchdata.run import ABLATIONS, markdown_table, run_benchmark
from zooctl.errors import InputError, UsageError
from zooctl.rig.synthetic import tube_asset

TINY = tiny_overrides()


def test_bench_make_ground_truth_is_consistent(tmp_path):
    """The saved masks are the projection of the saved vertices through the saved cameras."""
    import torch

    from zooctl.render.camera import Camera
    from zooctl.render.raster import rasterize

    asset = tube_asset(bones=3, name="tube")
    folder = make_video(asset, tmp_path, frames=13, size=48, seed=2)
    z = np.load(folder / "video.npz")
    assert z["frames"].shape == (13, 48, 48, 3) and z["flow"].shape == (12, 48, 48, 2)
    assert z["gt_novel_vertices"].shape == z["gt_vertices"].shape[1:]
    t = 7
    K = torch.as_tensor(z["intrinsics"][None], dtype=torch.float32)
    cam = Camera(
        K,
        torch.as_tensor(z["gt_cam_rotation"][t : t + 1], dtype=torch.float32),
        torch.as_tensor(z["gt_cam_translation"][t : t + 1], dtype=torch.float32),
        48,
        48,
    )
    sil = (
        rasterize(
            torch.as_tensor(z["gt_vertices"][t : t + 1]),
            torch.as_tensor(z["gt_faces"], dtype=torch.long),
            cam,
        )
        .mask[0]
        .numpy()
    )
    assert (sil == z["masks"][t]).mean() > 0.99
    # The camera moves (15-22.5 degrees per 12 frames) and the pose changes.
    assert not np.allclose(z["gt_cam_rotation"][0], z["gt_cam_rotation"][12])
    assert np.abs(z["gt_vertices"][12] - z["gt_vertices"][0]).max() > 1e-3
    assert json.loads((folder / "meta.json").read_text())["asset"] == "tube"
    # Held-out views: the same frames' vertices through the held-out cameras give their masks.
    assert z["gt_view_masks"].shape == (2, 13, 48, 48) and z["gt_view_rotation"].shape == (2, 13, 3, 3)
    for c in range(2):
        view = Camera(
            K,
            torch.as_tensor(z["gt_view_rotation"][c, t : t + 1], dtype=torch.float32),
            torch.as_tensor(z["gt_view_translation"][c, t : t + 1], dtype=torch.float32),
            48,
            48,
        )
        vm = rasterize(
            torch.as_tensor(z["gt_vertices"][t : t + 1]),
            torch.as_tensor(z["gt_faces"], dtype=torch.long),
            view,
        ).mask[0]
        assert (vm.numpy() == z["gt_view_masks"][c, t]).mean() > 0.99 and vm.any()
        assert not np.allclose(z["gt_view_rotation"][c, t], z["gt_cam_rotation"][t])


def test_bench_make_fov_sets_the_focal_and_is_recorded(tmp_path):
    """A narrower field of view is a longer focal, and the animal fills the frame as before."""
    import math

    asset = tube_asset(bones=3, name="tube")
    wide = make_video(asset, tmp_path / "wide", frames=2, size=48, seed=2, fov=60.0)
    narrow = make_video(asset, tmp_path / "narrow", frames=2, size=48, seed=2, fov=25.0)
    for folder, fov in ((wide, 60.0), (narrow, 25.0)):
        z = np.load(folder / "video.npz")
        assert z["intrinsics"][0] == pytest.approx(24 / math.tan(math.radians(fov / 2)), rel=1e-4)
        assert json.loads((folder / "meta.json").read_text())["fov"] == fov
        assert 0.05 < z["masks"][0].mean() < 0.9
    with pytest.raises(UsageError, match="--fov 200 is not a field of view"):
        make_video(asset, tmp_path / "bad", frames=2, size=48, fov=200.0)


def test_bench_run_table(tmp_path, store):
    from zooctl.store.bank import Bank

    tube = tube_asset(bones=3, name="tube")
    other = tube_asset(bones=2, name="tube2", radius=0.2)
    Bank(store).add(tube)
    Bank(store).add(other)
    make_video(tube, tmp_path / "v", frames=3, size=32, seed=0)
    res = run_benchmark(
        tmp_path / "v", store, ablations=["full", "no-flow"], template="tube2", overrides=TINY
    )
    assert [r["ablation"] for r in res["rows"]] == ["full", "no-flow"]
    row = res["rows"][0]
    assert row["template"] == "tube2" and 0 <= row["mask_iou"] <= 1 and row["miou"] is not None
    assert 0 <= row["novel_view_iou"] <= 1
    from zooctl.store.fits import FitStore

    record = FitStore(store).get("bench-tube-full")
    assert Image.open(record["outputs"]["novel_view_png"]).size[0] == 3 * 34  # input + 2 held-out
    table = markdown_table(res)
    assert "novel-view IoU" in table
    assert "| full | 1 |" in table and "no-flow" in table
    assert "Camera motion: estimated" in table
    own = run_benchmark(tmp_path / "v", store, own_template=True, known_camera=True, overrides=TINY)
    assert own["rows"][0]["template"] == "tube" and own["own_template"] and own["known_camera"]
    assert "each video's own asset" in markdown_table(own) and "Camera motion: known" in markdown_table(own)
    with pytest.raises(UsageError, match="exclude each other"):
        run_benchmark(tmp_path / "v", store, template="tube2", own_template=True)


def test_bench_run_names_a_broken_meta_json(tmp_path, store):
    """A benchmark video whose meta.json is not JSON, or not an object, is one clear error naming
    that file, whether the benchmark or the fit reads it first."""
    from zooctl.fit.inputs import load_bench_video

    folder = make_video(tube_asset(bones=2, name="tube"), tmp_path / "v", frames=2, size=32)
    for text, why in (("{bad", "is unreadable"), ("[]", "is not a JSON object")):
        (folder / "meta.json").write_text(text)
        with pytest.raises(InputError, match=f"meta.json {why}"):
            run_benchmark(tmp_path / "v", store, template="tube", overrides=TINY)
        with pytest.raises(InputError, match=f"meta.json {why}"):
            load_bench_video(folder)


def test_reanimation_uses_the_scale_of_the_frame_it_starts_from(tmp_path):
    """Re-animation poses the last frame's fit: a fit whose depth drifts on the other frames (a
    monocular fit is only known up to a scale per frame) must not move its scale."""
    import torch

    from zooctl.fit.config import FitConfig
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.metrics import evaluate_fit
    from zooctl.fit.run import fit_video

    asset = tube_asset(bones=3, name="tube")
    video = load_fit_video(make_video(asset, tmp_path / "v", frames=4, size=32, seed=0))
    res = fit_video(video, asset, FitConfig.from_dict(json.loads(json.dumps(TINY))))
    before = evaluate_fit(res, frames=4)
    with torch.no_grad():
        res.scene.root_translation[:-1] *= 2.0  # every frame but the last twice as far
    after = evaluate_fit(res, frames=4)
    assert after["reanimation"] == before["reanimation"]


def _fit_tiny(tmp_path):
    from zooctl.fit.config import FitConfig
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.run import fit_video

    asset = tube_asset(bones=3, name="tube")
    video = load_fit_video(make_video(asset, tmp_path / "v", frames=4, size=32, seed=0))
    return fit_video(video, asset, FitConfig.from_dict(json.loads(json.dumps(TINY))))


def test_novel_view_iou_scores_the_truth_high_and_a_mirror_low(tmp_path):
    """Projected through the held-out cameras, the true shape (placed in the input camera's frame)
    matches the held-out masks; the same shape mirrored in depth, which the input view cannot tell
    apart, does not."""
    from zooctl.fit.metrics import novel_view_iou

    res = _fit_tiny(tmp_path)
    gt = res.video.gt
    res.template = tube_asset(bones=3, name="tube")  # faces of the ground-truth mesh
    sel = np.array([0, 3])
    R, t = gt["cam_rotation"][sel], gt["cam_translation"][sel]
    cam_frame = np.einsum("sva,sba->svb", gt["vertices"][sel], R) + t[:, None]
    truth = novel_view_iou(res, sel, cam_frame, np.ones(2))
    assert truth is not None and min(truth) > 0.9
    z0 = cam_frame[..., 2:].mean(1, keepdims=True)
    mirrored = cam_frame.copy()
    mirrored[..., 2:] = 2 * z0 - cam_frame[..., 2:]
    assert max(novel_view_iou(res, sel, mirrored, np.ones(2))) < min(truth) - 0.05


def test_the_novel_view_sheet_shows_what_the_metric_compared(tmp_path):
    """The picture of `novel_view.png`: a row per frame, the input camera then each held-out one;
    the true shape leaves almost nothing orange (fit only) or blue (truth only), the mirrored one
    leaves both, in the held-out columns and not in the input one."""
    from zooctl.fit.metrics import held_out_silhouettes
    from zooctl.fit.outputs import _FIT_ONLY, _TRUTH_ONLY, novel_view_sheet

    res = _fit_tiny(tmp_path)
    gt = res.video.gt
    res.template = tube_asset(bones=3, name="tube")
    sel = np.array([0, 3])
    R, t = gt["cam_rotation"][sel], gt["cam_translation"][sel]
    cam_frame = np.einsum("sva,sba->svb", gt["vertices"][sel], R) + t[:, None]
    z0 = cam_frame[..., 2:].mean(1, keepdims=True)
    mirrored = cam_frame.copy()
    mirrored[..., 2:] = 2 * z0 - cam_frame[..., 2:]

    def wrong(views, col):  # pixels the fit and the truth disagree on in column ``col``
        return sum(int((f ^ g).sum()) for f, g in zip(views[col][1], views[col][2], strict=True))

    views = held_out_silhouettes(res, sel, cam_frame, np.ones(2), input_view=True)
    assert [v[0] for v in views] == ["input", "held-out 1 (90 deg off)", "held-out 2 (35 deg off)"]
    assert all(v[1].shape == v[2].shape == (2, 32, 32) for v in views)
    seen = held_out_silhouettes(res, sel, mirrored, np.ones(2), input_view=True)
    assert [wrong(views, c) for c in range(3)] == [0, 0, 0]
    # the input view barely tells a mirror in depth (perspective only); the held-out ones do
    assert min(wrong(seen, 1), wrong(seen, 2)) > 2 * wrong(seen, 0)
    sheet = novel_view_sheet(seen, [0, 3])
    assert sheet.shape == (36 + 2 * 34, 3 * 34, 3)
    held_out = sheet[36:, 34:]
    for colour in (_FIT_ONLY, _TRUTH_ONLY):
        assert (held_out == colour).all(-1).sum() > 5


def test_bench_folders_without_novel_views_say_n_a(tmp_path, store):
    from zooctl.store.bank import Bank

    tube = tube_asset(bones=3, name="tube")
    Bank(store).add(tube)
    folder = make_video(tube, tmp_path / "v", frames=3, size=32, seed=0)
    with np.load(folder / "video.npz") as z:  # a folder made before the held-out views
        np.savez(folder / "video.npz", **{k: z[k] for k in z.files if not k.startswith("gt_view_")})
    res = run_benchmark(tmp_path / "v", store, own_template=True, overrides=TINY)
    assert res["rows"][0]["novel_view_iou"] is None and res["rows"][0]["miou"] is not None
    assert "| n/a |" in markdown_table(res)


def test_overlay_turns_around_the_fit_at_a_fixed_time(tmp_path):
    from zooctl.fit.fitted_asset import fitted_asset
    from zooctl.fit.outputs import OUTLINE, overlay_frames

    res = _fit_tiny(tmp_path)
    asset = fitted_asset(res.scene, res.template, "tube-fit", res.video.fps)
    out = np.stack(list(overlay_frames(asset, res.input_camera(), res.video.frames, turn_frames=4)))
    T, W = res.video.num_frames, res.video.frames.shape[2]
    assert out.shape == (T + 4, 32, 64, 3)
    assert all((out[T + k, :, :W] == out[T // 2, :, :W]).all() for k in range(4))  # time stands still
    outline = (out[:T, :, :W] == OUTLINE).all(-1)  # the fit's silhouette outlined on every frame
    assert all(outline[t].any() for t in range(T)) and not (out[:T, :, W:] == OUTLINE).all(-1).any()
    assert not (out[T, :, W:] == out[T + 1, :, W:]).all()  # while the camera turns


def test_bench_run_pose_prior_option(tmp_path):
    from cli_helpers import zooctl

    from zooctl.cli.bench_fit import component_overrides

    assert component_overrides(None, None, "clips") == {"pose_prior": {"kind": "clips"}}
    assert component_overrides(None, None) is None
    r = zooctl("bench", "run", str(tmp_path), "--pose-prior", "bogus", store=tmp_path / "store")
    assert (
        r.code == 2
        and "pose_prior.kind 'bogus' must be one of none, rest, clips, motion" in r.err
        and "Traceback" not in r.err
    ), r.err


def test_bench_run_device_option(tmp_path):
    import torch
    from cli_helpers import zooctl

    from zooctl.cli.bench_fit import component_overrides

    assert component_overrides(None, None, None, "cuda") == {"device": "cuda"}
    r = zooctl("bench", "run", str(tmp_path), "--device", "gpu", store=tmp_path / "store")
    assert r.code == 2 and "device 'gpu' must be cpu, cuda or cuda:N" in r.err and "Traceback" not in r.err, (
        r.err
    )
    if not torch.cuda.is_available():  # one clear line, not one failed row per video
        r = zooctl("bench", "run", str(tmp_path), "--device", "cuda", store=tmp_path / "store")
        assert r.code == 2 and "no CUDA device" in r.err and "Traceback" not in r.err, r.err


def test_bench_run_config_file(tmp_path):
    from cli_helpers import zooctl

    from zooctl.cli.bench_fit import config_overrides

    cfg = tmp_path / "w.json"
    cfg.write_text('{"weights": {"pose_prior": 0.1}, "pose_prior": {"kind": "rest", "min_std_deg": 5}}')
    flags = {"pose_prior": {"kind": "clips"}}
    assert config_overrides(cfg, flags) == {
        "weights": {"pose_prior": 0.1},
        "pose_prior": {"kind": "clips", "min_std_deg": 5},  # the flag wins, the file's other field stays
    }
    assert config_overrides(None, flags) == flags
    (tmp_path / "bad.json").write_text('{"weights": {"no_such_term": 1}}')
    r = zooctl(
        "bench", "run", str(tmp_path), "--config", str(tmp_path / "bad.json"), store=tmp_path / "store"
    )
    assert r.code == 2 and "no_such_term" in r.err and "Traceback" not in r.err, r.err
    (tmp_path / "preset.json").write_text('{"preset": "quality"}')
    r = zooctl(
        "bench", "run", str(tmp_path), "--config", str(tmp_path / "preset.json"), store=tmp_path / "store"
    )
    assert r.code == 2 and "--preset" in r.err, r.err


def test_clip_motion_plays_the_assets_clip_in_place_without_jumps():
    """`bench make --motion clips`: the clip's own poses at its own frame rate, forwards then
    backwards (no jump where a loop would restart), the roots held at their rest translation."""
    from zooctl.benchdata.make import clip_motion
    from zooctl.geometry import decompose_trs
    from zooctl.procedural import build_animal

    asset = build_animal("quadruped", name="q")
    clip = asset.clips[sorted(asset.clips)[0]]
    asset.clips = {clip.name: clip}
    frames = 3 * clip.num_frames  # long enough to turn back twice
    local, name = clip_motion(asset, frames, np.random.default_rng(0), fps=clip.fps)
    assert name == clip.name and local.shape == (frames, asset.num_joints, 4, 4)
    t, q, _ = decompose_trs(local)
    roots = asset.parents < 0
    np.testing.assert_allclose(
        t[:, roots], np.broadcast_to(asset.rest_trs()[0][roots], t[:, roots].shape), atol=1e-6
    )
    # Every frame is (close to) one of the clip's: at the clip's rate the steps fall between its frames.
    dots = np.abs(np.einsum("tjc,kjc->tkj", q, clip.rotations)).min(-1).max(-1)
    assert (dots > 0.99).all()

    # No step moves a joint further than the clip's own largest step between two frames.
    def steps(r):
        return np.degrees(2 * np.arccos(np.clip(np.abs((r[1:] * r[:-1]).sum(-1)), 0, 1))).max()

    assert steps(q) <= steps(clip.rotations) + 1e-3


def test_bench_make_clips_motion_is_recorded_and_falls_back_without_clips(tmp_path):
    from zooctl.procedural import build_animal

    folder = make_video(
        build_animal("quadruped", name="q"), tmp_path, frames=4, size=32, seed=0, motion="clips"
    )
    meta = json.loads((folder / "meta.json").read_text())
    assert meta["motion"] == "clips" and meta["clip"]
    tube = tube_asset(bones=3, name="tube")
    tube.clips = {}
    meta = json.loads(
        (make_video(tube, tmp_path, frames=3, size=32, motion="clips") / "meta.json").read_text()
    )
    assert meta["motion"] == "random" and meta["clip"] is None
    with pytest.raises(UsageError, match="motion"):
        make_video(tube, tmp_path, frames=3, size=32, motion="walk")


def test_a_named_clip_is_the_one_filmed(tmp_path):
    """`make demo` films the starter animal walking: `make_video(..., clip="walk")` plays that clip
    (meta.json says so), and a clip the animal lacks is a clear error naming the ones it has."""
    from zooctl.procedural import build_animal

    asset = build_animal("quadruped", name="q")
    folder = make_video(asset, tmp_path, frames=4, size=48, seed=3, motion="clips", clip="walk")
    assert json.loads((folder / "meta.json").read_text())["clip"] == "walk"
    with pytest.raises(UsageError, match="no clip 'gallop'.*") as err:
        make_video(asset, tmp_path / "b", frames=4, size=48, motion="clips", clip="gallop")
    assert "walk" in err.value.hint


def _edge_lengths(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return np.linalg.norm(vertices[e[:, 0]] - vertices[e[:, 1]], axis=1)


def test_keep_shape_fits_only_the_pose_and_keeps_the_templates_shape_and_skinning(tmp_path):
    """`zooctl fit --keep-shape` (`FitConfig.keep_shape`, `bench run --ablation shape-kept`): the
    exported character is the template scaled by the fit's global scale, with the template's
    skinning, while the default fit of the same video reshapes both; the pose is fitted in both."""
    from zooctl.fit.config import FitConfig
    from zooctl.fit.fitted_asset import fitted_asset
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.run import fit_video

    template = tube_asset(bones=3, name="tube")
    video = load_fit_video(
        make_video(tube_asset(bones=3, radius=0.3, name="fat"), tmp_path / "v", frames=4, size=32)
    )
    shapes = {}
    for kept in (False, True):
        cfg = FitConfig.from_dict(json.loads(json.dumps(TINY)))
        res = fit_video(video, template, cfg.keep_shape() if kept else cfg)
        out = fitted_asset(res.scene, res.template, "fit", res.video.fps)
        ratio = _edge_lengths(out.vertices, out.faces) / _edge_lengths(template.vertices, template.faces)
        shapes[kept] = (
            ratio.std() / ratio.mean(),
            np.abs(out.skin_weights_dense() - template.skin_weights_dense()).max(),
            out,
        )
    spread, skin_drift, out = shapes[True]
    assert spread < 1e-4 and skin_drift < 1e-5  # one scale for every edge; the template's weights
    assert shapes[False][0] > 1e-4 and shapes[False][1] > 1e-3  # the default reshapes and reskins
    q = out.clips["fit"].rotations
    assert np.abs(q[1:, 1:] - q[:1, 1:]).max() > 1e-3  # the joints still move from frame to frame
    bench = FitConfig.from_dict(json.loads(json.dumps(ABLATIONS["shape-kept"])))
    assert bench.ablation == FitConfig().keep_shape().ablation


def test_axis_tilt_reads_how_far_the_longest_axis_leaves_the_image_plane():
    from zooctl.fit.metrics import axis_tilt

    rng = np.random.default_rng(0)
    body = rng.normal(size=(500, 3)) * [1.0, 0.2, 0.1]  # long along x
    turn = np.radians(40)
    rot = np.array([[np.cos(turn), 0, np.sin(turn)], [0, 1, 0], [-np.sin(turn), 0, np.cos(turn)]])
    assert axis_tilt(body) < 2
    assert abs(axis_tilt(body @ rot.T) - 40) < 2
    assert axis_tilt(body[:, [1, 2, 0]]) > 88  # pointing at the camera


def test_a_fit_records_its_tilt_against_the_truths(tmp_path):
    from zooctl.fit.metrics import evaluate_fit

    res = _fit_tiny(tmp_path)
    m = evaluate_fit(res, frames=2, reanimate_iters=1)
    assert len(m["axis_tilt"]["fit"]) == len(m["axis_tilt"]["truth"]) == 2
    want = np.mean(np.subtract(m["axis_tilt"]["fit"], m["axis_tilt"]["truth"]))
    assert abs(m["tilt_error"] - want) < 0.1 and -90 <= m["tilt_error"] <= 90


def test_a_figure_label_is_white_text_outlined_where_it_is_written():
    """Every figure's cell label (`novel_view.png`, the overlay): the dark outline ends where the
    white text ends (a thicker outline stroke once ran a glyph past it: '0.88' read '0.883')."""
    from zooctl.fit.outputs import _label

    img = _label(np.full((320, 320, 3), 128, np.uint8), "frame 0, input: IoU 0.88")
    white = np.nonzero((img > 200).all(-1).any(0))[0]
    dark = np.nonzero((img < 40).all(-1).any(0))[0]
    assert len(white) > 50 and len(dark) > 50
    assert dark.max() <= white.max() + 2 and dark.min() >= white.min() - 2
