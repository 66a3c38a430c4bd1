"""`video add`'s check that automatic masks hold an animal (`zooctl.video.animal_check`)."""

from __future__ import annotations

import json

import cv2
import numpy as np
from cli_helpers import run_inprocess
from conftest import VIDEOS_DIR, needs_shared_videos

from zooctl.video.animal_check import (
    MAX_EMPTY_SHARE,
    MIN_LOOKS,
    MIN_REGIONS,
    check_animal,
    crop_looks,
    look_frames,
    mask_crop,
    unsure_line,
)


def test_the_crop_is_the_square_round_the_mask_cut_by_the_frame():
    frame = np.arange(100 * 200 * 3, dtype=np.uint32).reshape(100, 200, 3).astype(np.uint8)
    mask = np.zeros((100, 200), bool)
    mask[40:60, 90:130] = True  # 20 x 40: the square's side is 1.25 x 39 px
    crop = mask_crop(frame, mask)
    assert crop.shape[:2] == (48, 48)
    mask[:] = False
    mask[0:10, 0:80] = True  # at the corner: cut by the frame's edges
    crop = mask_crop(frame, mask)
    assert crop.shape[0] < crop.shape[1] and np.array_equal(crop, frame[: crop.shape[0], : crop.shape[1]])
    assert mask_crop(frame, np.zeros_like(mask)) is None
    assert list(look_frames(40)) == [0, 7, 15, 23, 31, 39] and list(look_frames(3)) == [0, 1, 2]


def test_the_rule_needs_several_regions_and_a_poor_look_or_empty_frames():
    frames = np.zeros((10, 32, 32, 3), np.uint8)
    empty = np.zeros((10, 32, 32), bool)  # every look 0, without running the classifier
    few = {"animals_seen": MIN_REGIONS, "empty_frames": []}
    assert check_animal(frames, empty, few)["unsure"]
    assert not check_animal(frames, empty, {**few, "animals_seen": MIN_REGIONS - 1})["unsure"]
    # a segmenter without the localiser's regions is never judged
    assert not check_animal(frames, empty, {"empty_frames": []})["unsure"]
    check = check_animal(frames, empty, {**few, "empty_frames": list(range(10))})
    assert check["empty_share"] == 1.0 > MAX_EMPTY_SHARE and check["looks"] == 0.0
    line = unsure_line(check, "rocks")
    assert line.startswith("warning: rocks's masks may not hold an animal") and "100% of the frames" in line
    assert unsure_line(check_animal(frames, empty, {"empty_frames": []}), "rocks") is None
    assert unsure_line(None, "rocks") is None


def _davis(name: str, frames: int = 6):
    files = sorted((VIDEOS_DIR / name / "JPEGImages").glob("*.jpg"))[:frames]
    rgb = np.stack([cv2.imread(str(f))[..., ::-1] for f in files])
    truth = np.stack(
        [
            cv2.imread(str(VIDEOS_DIR / name / "Annotations" / (f.stem + ".png")), cv2.IMREAD_GRAYSCALE) > 0
            for f in files
        ]
    )
    return rgb, truth


@needs_shared_videos
def test_the_classifier_tells_an_animal_s_crop_from_the_scene_s():
    """The truth's masks of the DAVIS black swan look like an animal; the same masks moved onto the
    water and leaves the swan never swims into (its right-hand 280 px) do not."""
    rgb, truth = _davis("blackswan")
    _, looks = crop_looks(rgb, truth)
    assert min(looks) > MIN_LOOKS
    moved = np.zeros_like(truth)
    for i, m in enumerate(truth):
        ys, xs = np.nonzero(m)
        h, w = min(int(np.ptp(ys)), 200), min(int(np.ptp(xs)), 200)
        moved[i, 20 : 20 + h, 600 : 600 + w] = True
    _, looks = crop_looks(rgb, moved)
    assert max(looks) < MIN_LOOKS
    # the swan's own masks, two regions: frames left empty beyond the share make them unsure
    seen = {"animals_seen": MIN_REGIONS}
    ok = check_animal(rgb, truth, {**seen, "empty_frames": [0]})  # 1 of 6 empty
    assert ok["looks"] > MIN_LOOKS and not ok["unsure"]
    gaps = check_animal(rgb, truth, {**seen, "empty_frames": [0, 1]})  # 2 of 6
    assert gaps["looks"] > MIN_LOOKS and gaps["empty_share"] > MAX_EMPTY_SHARE and gaps["unsure"]
    line = unsure_line(gaps, "swan")
    assert "33% of the frames have no mask" in line and "classifier gives" not in line


def _scene(folder, seed: int = 0, t: int = 16, size: int = 240):
    """A clip of a natural scene with no animal, filmed by a camera turning 2 degrees a frame."""
    from zooctl.benchdata.appearance import world_backgrounds

    f = size / (2 * np.tan(np.radians(20)))
    e = np.radians(10.0)
    tilt = np.array([[1, 0, 0], [0, np.cos(e), -np.sin(e)], [0, np.sin(e), np.cos(e)]])
    turns = []
    for i in range(t):
        a = np.radians(2.0 * i)
        turns.append(tilt @ np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]]))
    clip = world_backgrounds(
        np.random.default_rng(seed), np.array([f, f, size / 2, size / 2]), np.array(turns), (size, size)
    )
    folder.mkdir(parents=True)
    for i, frame in enumerate(clip):
        cv2.imwrite(str(folder / f"{i:05d}.png"), frame[..., ::-1])
    return folder


def test_video_add_of_a_scene_without_an_animal_warns_and_a_fit_repeats_it(tmp_path, store, capsys):
    from fit_helpers import tiny_fit_config

    from zooctl.fit.job import fit_job
    from zooctl.rig.synthetic import tube_asset
    from zooctl.store.bank import Bank

    r = run_inprocess(capsys, "video", "add", str(_scene(tmp_path / "hills")), "--name", "hills")
    assert r.code == 0, r.err
    assert "added hills" in r.out and "warning: hills's masks may not hold an animal" in r.err
    assert "warning" not in r.out  # said on stderr, after the summary line
    check = run_inprocess(capsys, "video", "show", "hills", "--json").json()["seeding"]["animal_check"]
    assert check["unsure"] and check["regions"] >= MIN_REGIONS and check["rule"]["min_looks"] == MIN_LOOKS
    assert "UNSURE the masks hold an animal" in run_inprocess(capsys, "video", "show", "hills").out
    # a box says where the animal is: not checked
    r = run_inprocess(
        capsys, "video", "add", str(tmp_path / "hills"), "--name", "boxed", "--box", "60,60,80,80"
    )
    assert r.code == 0 and "warning" not in r.err
    assert "animal_check" not in run_inprocess(capsys, "video", "show", "boxed", "--json").json()["seeding"]

    Bank(store).add(tube_asset(bones=3, name="tube"))
    rec = fit_job("hills", store, tiny_fit_config(), name="h", template="tube", outputs=("loss",))
    assert rec["notes"][0].startswith("hills's masks may not hold an animal")

    # a video stored before the check existed: the fit makes it, as video add would have (the
    # file opens for writing at once: the first fit closed it, not the garbage collector)
    import h5py

    from zooctl.store.videos import VideoStore

    with h5py.File(VideoStore(store).path("hills"), "r+") as f:
        seg = json.loads(f.attrs["segmenter"])
        del seg["animal_check"]
        f.attrs["segmenter"] = json.dumps(seg)
    rec = fit_job("hills", store, tiny_fit_config(), name="h2", template="tube", outputs=("loss",))
    assert rec["notes"][0] == "hills's masks" + unsure_line(check, "hills").split("'s masks", 1)[1]
    # and `video show` makes it too, says so, and stores nothing
    shown = run_inprocess(capsys, "video", "show", "hills", "--json").json()["seeding"]["animal_check"]
    assert shown["made_now"] and shown["looks"] == check["looks"] and shown["unsure"]
    out = run_inprocess(capsys, "video", "show", "hills").out
    assert "UNSURE the masks hold an animal (made now: the video was stored before the check" in out
    with h5py.File(VideoStore(store).path("hills"), "r") as f:
        assert "animal_check" not in json.loads(f.attrs["segmenter"])


def test_video_add_of_a_rendered_animal_does_not_warn(tmp_path, store, capsys):
    """A procedural quadruped, textured, over the same kind of scene, turned by the same kind of
    camera: one clear region, crops that look like an animal."""
    from zooctl.benchdata.make import make_video
    from zooctl.procedural import build_animal

    video = make_video(
        build_animal("quadruped", seed=1),
        tmp_path,
        frames=16,
        size=240,
        seed=1,
        appearance="textured",
        background="world",
    )
    r = run_inprocess(capsys, "video", "add", str(video / "video.mp4"), "--name", "dog")
    assert r.code == 0, r.err
    assert "warning" not in r.out + r.err
    check = run_inprocess(capsys, "video", "show", "dog", "--json").json()["seeding"]["animal_check"]
    assert not check["unsure"] and check["looks"] > MIN_LOOKS


def test_a_user_s_masks_are_not_checked(tmp_path, store, capsys):
    from video_helpers import write_png_davis

    rng = np.random.default_rng(0)
    frames = rng.integers(0, 255, (4, 48, 64, 3), dtype=np.uint8)
    m = np.zeros((4, 48, 64), bool)
    m[:, 10:30, 10:40] = True
    folder = write_png_davis(tmp_path / "noise", frames, m)
    assert run_inprocess(capsys, "video", "add", str(folder), "--name", "noise").code == 0
    info = run_inprocess(capsys, "video", "show", "noise", "--json").json()
    assert "animal_check" not in (info.get("seeding") or {})
