"""A fit of another source scored against a benchmark video's truth (`fit_job`'s ``truth``,
`bench/user_path.py`): the fit reads its own source's masks, the 3D metrics and
``mask_iou_truth`` come from the benchmark folder."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from fit_helpers import small_quadruped_video, write_davis_folder

from zooctl.errors import UsageError
from zooctl.fit.config import FitConfig, preset
from zooctl.fit.inputs import load_fit_video
from zooctl.fit.job import fit_job

pytestmark = pytest.mark.usefixtures("one_thread")


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    root = tmp_path_factory.mktemp("truth")
    store, folder, cfg = small_quadruped_video(root)
    video = load_fit_video(folder)
    # the masks a user's segmenter might give: the true ones with their lower third cut off
    masks = video.masks.copy()
    for m in masks:
        ys = np.nonzero(m.any(1))[0]
        m[ys[0] + 2 * (ys[-1] - ys[0]) // 3 :] = False
    davis = write_davis_folder(root / "davis", video.frames, masks)
    return store, folder, FitConfig.from_dict(json.loads(cfg.read_text()), preset("fast")), davis


def test_the_fit_reads_its_own_masks_and_is_scored_against_the_truth(bench):
    store, folder, cfg, davis = bench
    rec = fit_job(str(davis), store, cfg, name="cut", template="quadruped", outputs=(), truth=folder)
    m = rec["metrics"]
    assert rec["truth"] == str(folder.resolve())
    assert rec["mask_source"] != "given"  # read from the stored video, not the benchmark's
    # against the cut masks it read and against the whole animal: not the same figure
    assert 0 < m["mask_iou_truth"] <= 1 and abs(m["mask_iou_truth"] - m["mask_iou"]) > 0.02
    for k in ("novel_view_iou", "miou", "joint"):
        assert m[k] is not None and np.isfinite(m[k]), k
    # no lens known (a DAVIS folder of plain JPEGs): a normal lens's focal, the frame's diagonal,
    # kept by the fit; the fit says so, with the fix
    assert rec["focal"] == {"from": "normal", "px": pytest.approx(math.hypot(96, 96))}
    assert rec["camera"]["focal_px"] == pytest.approx(math.hypot(96, 96), rel=1e-4)
    (note,) = [n for n in rec["notes"] if "no lens was given or recorded" in n]
    assert "a normal lens's" in note and "136 px" in note and "--focal PX" in note and "--lens MM" in note
    # camera.focal_guess search: the camera search's pick, as before
    cfg_search = FitConfig.from_dict(cfg.to_dict())
    cfg_search.camera.focal_guess = "search"
    plain = fit_job(str(davis), store, cfg_search, name="plain", template="quadruped", outputs=())
    assert "mask_iou_truth" not in plain["metrics"] and "miou" not in plain["metrics"]
    assert plain["truth"] is None
    assert plain["focal"] == {"from": "estimated", "px": plain["camera"]["focal_px"]}
    (note,) = [n for n in plain["notes"] if "no lens was given or recorded" in n]
    assert f"estimated from the silhouettes, {plain['camera']['focal_px']:.0f} px" in note
    # the benchmark's own folder gives the focal: no such note
    given = fit_job(str(folder), store, cfg, name="given", template="quadruped", outputs=())
    assert not any("no lens was given" in n for n in given["notes"])
    assert given["focal"]["from"] == "video"


def test_a_truth_that_is_not_the_same_video_is_refused(bench, tmp_path):
    store, folder, cfg, davis = bench
    video = load_fit_video(folder)
    short = write_davis_folder(tmp_path / "short", video.frames[:6], video.masks[:6])
    with pytest.raises(UsageError, match="has 6 frames of 96x96, its truth 10 of 96x96"):
        fit_job(str(short), store, cfg, name="short", template="quadruped", outputs=(), truth=folder)
    with pytest.raises(UsageError, match="not a `zooctl bench make` video folder"):
        fit_job(str(davis), store, cfg, name="none", template="quadruped", outputs=(), truth=tmp_path)


def test_bench_user_path_adds_the_mp4_and_scores_the_fit_against_the_truth(bench, tmp_path):
    """`bench/user_path.py`: `zooctl video add` of the benchmark's mp4 (automatic masks), the fit
    from the store, its rows scored against the truth."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    store, folder, cfg, _ = bench
    (tmp_path / "small.json").write_text(json.dumps(cfg.to_dict()))
    repo = Path(__file__).resolve().parent.parent
    out = tmp_path / "rows.json"
    env = dict(os.environ, ZOOCTL_STORE=str(store))
    args = [sys.executable, str(repo / "bench" / "user_path.py"), str(folder.parent), "--own-template"]
    args += ["--config", str(tmp_path / "small.json"), "--json", str(out)]
    subprocess.run(args, check=True, env=env, capture_output=True)
    (row,) = json.loads(out.read_text())["rows"]
    assert row["video"] == folder.name and row["template"] == "quadruped"
    assert 0.3 < row["mask_j"] <= 1  # the store's own masks against the true ones
    for k in ("mask_iou", "mask_iou_read", "novel_view_iou", "miou", "joint"):
        assert row[k] is not None and np.isfinite(row[k]), k
    # the true masks as the user's own, the true focal: the stored masks are the truth's
    subprocess.run(args + ["--masks", "truth", "--focal", "truth"], check=True, env=env, capture_output=True)
    (row,) = json.loads(out.read_text())["rows"]
    assert row["mask_j"] > 0.99
    fit = json.loads((store / "fits" / f"user-{folder.name}-truth-truth" / "fit.json").read_text())
    assert fit["config"]["camera"]["focal"] == pytest.approx(float(load_fit_video(folder).intrinsics[0]))


def test_a_lens_the_frames_record_gives_the_focal(bench, tmp_path):
    """A frame folder whose first image's Exif names the benchmark camera's lens: the fit takes its
    focal from it (not estimated), says so, and keeps it."""
    from PIL import Image

    from zooctl.video.lens import focal_pixels

    store, folder, cfg, _ = bench
    video = load_fit_video(folder)
    H, W = video.size
    true_px = float(video.intrinsics[0])
    f35 = true_px / focal_pixels(1.0, W, H)  # the 35 mm-equivalent focal length of that camera
    davis = write_davis_folder(tmp_path / "exif", video.frames, video.masks)
    first = davis / "JPEGImages" / "00000.jpg"
    with Image.open(first) as im:
        exif = im.getexif()
        exif.get_ifd(0x8769)[41989] = round(f35)
        im.save(first, exif=exif, quality=95)
    rec = fit_job(str(davis), store, cfg, name="exif", template="quadruped", outputs=(), truth=folder)
    px = focal_pixels(round(f35), W, H)
    assert rec["focal"] == {
        "from": "lens",
        "lens": {"focal_35mm": float(round(f35)), "lens_model": None, "from": "exif"},
        "px": pytest.approx(px),
    }
    assert rec["config"]["camera"]["focal"] == pytest.approx(px)
    assert rec["camera"]["focal_px"] == pytest.approx(px, rel=1e-4)  # given focals are not learned
    assert abs(px / true_px - 1) < 0.02  # the lens rounded to whole millimetres
    assert (
        f"focal {px:.0f} px from the lens: {round(f35)} mm 35 mm-equivalent (the first frame's Exif)"
        in rec["notes"]
    )
    assert not any("no lens was given" in n for n in rec["notes"])
    # --lens overrides it, --focal both; the record says which
    cfg2 = FitConfig.from_dict(cfg.to_dict())
    cfg2.camera.lens_35mm = 2.0 * round(f35)
    rec = fit_job(str(davis), store, cfg2, name="exif2", template="quadruped", outputs=())
    assert rec["focal"]["lens"]["from"] == "config" and rec["focal"]["px"] == pytest.approx(2 * px)


def test_bench_statue_scores_the_animal_frozen_at_its_first_frame(bench, tmp_path):
    """`bench/statue.py`: frame 0's true surface held still, scored as a fit is. On frame 0 it is
    the truth (every camera sees the true masks); later the animal moves away from it."""
    import subprocess
    import sys
    from pathlib import Path

    _, folder, _, _ = bench
    out = tmp_path / "statue.json"
    script = Path(__file__).resolve().parent.parent / "bench" / "statue.py"
    subprocess.run(
        [sys.executable, str(script), str(folder.parent), "--json", str(out)], check=True, capture_output=True
    )
    (row,) = json.loads(out.read_text())["rows"]
    assert row["video"] == folder.name and row["frames_evaluated"][0] == 0
    assert row["input_view_iou_per_frame"][0] == 1.0
    assert [v[0] for v in row["novel_view_iou_per_frame"]] == [1.0, 1.0]
    later = row["input_view_iou_per_frame"][1:] + [x for v in row["novel_view_iou_per_frame"] for x in v[1:]]
    assert min(later) < 0.95 and 0 < row["novel_view_iou"] < 1 and 0 < row["miou"] < 1


def test_bench_orientation_bound_scores_each_fit_mirrored_and_turned(bench, tmp_path):
    """`bench/orientation_bound.py`: the mirror keeps every projected point where it was and turns the
    body's depth over (twice is the body again); `best_rotation` undoes a turn from whichever of its
    starts; on a stored fit of a benchmark video it reports the fit's own novel view, the mirror's,
    the better of the two per frame, and the fit turned to the truth's surface."""
    import importlib.util
    import subprocess
    import sys
    from pathlib import Path

    from zooctl.geometry import quat_to_matrix

    script = Path(__file__).resolve().parent.parent / "bench" / "orientation_bound.py"
    spec = importlib.util.spec_from_file_location("orientation_bound", script)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(200, 3)) * [0.3, 0.2, 0.5] + [0.1, -0.2, 4.0]
    flip = mod.depth_mirror_points(pts)
    np.testing.assert_allclose(flip[:, :2] / flip[:, 2:], pts[:, :2] / pts[:, 2:], atol=1e-12)
    np.testing.assert_allclose(flip[:, 2], pts[:, 2].max() + pts[:, 2].min() - pts[:, 2], atol=1e-12)
    np.testing.assert_allclose(mod.depth_mirror_points(flip), pts, atol=1e-9)
    # a long lumpy body turned 120 degrees about a slanted axis: the rotation found turns it back
    body = rng.normal(size=(400, 3)) * [1.0, 0.4, 0.15] + [0.3, 0.0, 0.0] * (rng.random((400, 1)) > 0.7)
    axis = np.array([1.0, 2.0, 0.5]) / np.linalg.norm([1.0, 2.0, 0.5])
    turn = quat_to_matrix(np.concatenate([[np.cos(1.05)], np.sin(1.05) * axis]))
    R = mod.best_rotation(body @ turn.T, body)
    np.testing.assert_allclose(R @ turn, np.eye(3), atol=0.05)

    store, folder, cfg, _ = bench
    cfg = FitConfig.from_dict(cfg.to_dict())
    cfg.checkpoint_every = 1  # the fit's last state kept, as a benchmark's long fit keeps it
    rec = fit_job(str(folder), store, cfg, name="flip", template="quadruped", outputs=())
    out = tmp_path / "flip.jsonl"
    run = subprocess.run(
        [sys.executable, str(script), "--store", str(store), "flip", "--json", str(out)],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, run.stderr[-2000:]
    row, summary = (json.loads(line) for line in out.read_text().splitlines())
    assert row["fit"] == "flip" and row["novel"] == pytest.approx(rec["metrics"]["novel_view_iou"])
    assert np.mean(row["novel_frames"]) == pytest.approx(row["novel"], abs=1e-3)  # rounded per frame
    assert row["novel_better"] >= max(row["novel"], row["novel_mirrored"]) - 1e-9
    assert row["novel_mirrored"] != pytest.approx(row["novel"])  # the mirror is another view
    assert 0 < row["novel_rotated"] <= 1 and len(row["rotated_frames"]) == len(row["frames"])
    assert summary["fits"] == 1 and summary["frames"] == len(row["frames"])
