"""The HDF5 video store and `zooctl video ...`: layout (schema-validated), atomicity, CLI end to end."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import run_inprocess
from conftest import VIDEOS_DIR, needs_shared_videos
from PIL import Image
from video_helpers import assert_same_video, iou, moving_object_video

from zooctl.errors import AlreadyExistsError, InputError, NotFoundError
from zooctl.io.video import probe_codec, write_mp4
from zooctl.store.h5 import describe_h5
from zooctl.store.videos import VideoStore
from zooctl.video.ingest import AddOptions, add_video

SCHEMAS = Path(__file__).resolve().parents[1] / "schemas"


def validate(instance, schema_name):
    import jsonschema

    schema = json.loads((SCHEMAS / schema_name).read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    jsonschema.validate(instance, schema)


def snapshot(root: Path) -> dict[str, bytes]:
    """Every file under the store (the lock file aside), for "the store is unchanged" checks."""
    return {
        str(p.relative_to(root)): p.read_bytes()
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.name != ".lock"
    }


@pytest.fixture(scope="module")
def synthetic_folder(tmp_path_factory):
    frames, masks = moving_object_video(t=6, h=96, w=128)
    root = tmp_path_factory.mktemp("syn")
    (root / "JPEGImages").mkdir()
    (root / "Annotations").mkdir()
    for i, (f, m) in enumerate(zip(frames, masks)):
        Image.fromarray(f).save(root / "JPEGImages" / f"{i:05d}.png")
        Image.fromarray(m.astype(np.uint8) * 255).save(root / "Annotations" / f"{i:05d}.png")
    return root, frames, masks


def test_add_get_list_remove_and_schemas(store, synthetic_folder):
    folder, frames, masks = synthetic_folder
    vs = VideoStore.open(store)
    summary = add_video(vs, folder, AddOptions(name="syn"))
    assert summary["segmenter"] == "masks" and summary["frames"] == 6 and vs.names() == ["syn"]
    rec = vs.get("syn")
    assert np.array_equal(rec.frames, frames) and np.array_equal(rec.masks, masks)  # PNG frames: lossless
    assert rec.flow_forward.shape == (5, 96, 128, 2) and rec.occlusion_backward.dtype == bool
    assert rec.boxes[0].tolist() == list(_box(masks[0]))
    assert rec.source["kind"] == "davis" and rec.source["original_width"] == 128
    validate(describe_h5(vs.path("syn")), "video_h5.schema.json")
    validate(json.loads(vs.index_path.read_text()), "video_index.schema.json")
    with pytest.raises(AlreadyExistsError):
        add_video(vs, folder, AddOptions(name="syn"))
    add_video(vs, folder, AddOptions(name="syn", segmenter="grabcut", replace=True))
    assert vs.summary("syn")["segmenter"] == "grabcut"
    assert iou(vs.get("syn", what=("masks",)).masks, masks) > 0.8
    vs.remove("syn")
    assert vs.names() == [] and not vs.path("syn").exists()
    with pytest.raises(NotFoundError, match="no video named"):
        vs.get("syn")


def _box(m):
    ys, xs = np.nonzero(m)
    return xs.min(), ys.min(), xs.max() - xs.min() + 1, ys.max() - ys.min() + 1


def test_failures_leave_the_store_unchanged(store, synthetic_folder, tmp_path):
    folder, frames, masks = synthetic_folder
    vs = VideoStore.open(store)
    add_video(vs, folder, AddOptions(name="keep"))
    before = snapshot(store)
    one = tmp_path / "one"
    one.mkdir()
    Image.fromarray(frames[0]).save(one / "0.png")
    short = tmp_path / "short"
    short.mkdir()
    for i, m in enumerate(masks[:3]):
        Image.fromarray(m.astype(np.uint8) * 255).save(short / f"{i}.png")
    (tmp_path / "empty.mp4").write_bytes(b"")
    blank = save_blank_masks(tmp_path / "blank", len(frames), masks.shape[1:])
    cases = [
        (one, AddOptions(name="one"), "gives only 1 frame"),
        (folder / "JPEGImages", AddOptions(name="short", masks=short), "3 masks"),
        (tmp_path / "empty.mp4", AddOptions(name="empty"), "is empty"),
        (folder, AddOptions(name="keep"), "already in the store"),
        (
            folder / "JPEGImages",
            AddOptions(name="blank", masks=blank),
            "found no animal in any of the 6 frames",
        ),
        (folder, AddOptions(name="bad name!"), "invalid video name"),
    ]
    for path, opts, message in cases:
        with pytest.raises((InputError, AlreadyExistsError), match=message):
            add_video(vs, path, opts)
        assert snapshot(store) == before, message
    assert not list((store / "videos").glob(".*.tmp"))


def _record(t=12, h=40, w=56):
    from zooctl.store.videos import VideoRecord

    rng = np.random.default_rng(1)
    masks = np.zeros((t, h, w), bool)
    masks[:, 10:30, 15:40] = True
    return VideoRecord(
        "bg",
        rng.integers(0, 255, (t, h, w, 3), dtype=np.uint8),
        masks,
        rng.normal(0, 2, (t - 1, h, w, 2)).astype(np.float32),
        rng.normal(0, 2, (t - 1, h, w, 2)).astype(np.float32),
        rng.random((t - 1, h, w)) > 0.9,
        rng.random((t - 1, h, w)) > 0.9,
        24.0,
        {"path": "x", "kind": "images", "sha256": "0" * 64},
        np.arange(t),
        {"name": "masks"},
        {"name": "dis"},
    )


def publish(store, writer, rec, name="bg") -> None:
    """Give ``writer`` the masks of ``rec``, finish it and publish it in ``store`` as ``name``."""
    for i, m in enumerate(rec.masks):
        writer.set_mask(i, m)
    summary = writer.finish(name, rec.fps, rec.source, rec.source_indices, rec.segmenter, rec.flow_estimator)
    store.add_written(name, writer, summary)


def test_a_file_written_a_chunk_at_a_time_equals_one_written_at_once(store, tmp_path):
    """`VideoWriter` (what `video add` streams into) makes the file `add` makes from memory:
    same arrays, same layout (schema-validated), published with its index entry."""
    rec = _record()
    one, streamed = VideoStore.open(tmp_path / "one"), VideoStore.open(store)
    one.add(rec)
    writer = streamed.begin_file("bg", (56, 40))
    try:
        for i in range(0, 12, 5):  # chunks that do not divide the clip
            writer.add_frames(rec.frames[i : i + 5])
        for i in range(0, 11, 4):
            parts = (rec.flow_forward, rec.flow_backward, rec.occlusion_forward, rec.occlusion_backward)
            writer.add_flow(*(p[i : i + 4] for p in parts))
        publish(streamed, writer, rec)
    finally:
        writer.discard()
    a, b = one.get("bg"), streamed.get("bg")
    assert_same_video(a, b)
    assert describe_h5(one.path("bg")) == describe_h5(streamed.path("bg"))
    validate(describe_h5(streamed.path("bg")), "video_h5.schema.json")
    assert streamed.summary("bg")["bytes"] == streamed.path("bg").stat().st_size
    assert not list((store / "videos").glob(".*.tmp*"))  # the temporary became the file


def test_an_incomplete_written_file_is_refused_and_removed(store):
    rec = _record()
    vs = VideoStore.open(store)
    writer = vs.begin_file("bg", (56, 40))
    writer.add_frames(rec.frames)
    with pytest.raises(ValueError, match="incomplete video file: 12 frames, 0 flow pairs"):
        writer.finish("bg", rec.fps, rec.source, rec.source_indices, rec.segmenter, rec.flow_estimator)
    writer.discard()
    writer.discard()  # twice: no-op
    assert vs.names() == [] and not list((store / "videos").iterdir())


def save_blank_masks(folder: Path, n: int, shape) -> Path:
    folder.mkdir()
    for i in range(n):
        Image.fromarray(np.zeros(shape, np.uint8)).save(folder / f"{i}.png")
    return folder


def test_cli_end_to_end(store, synthetic_folder, tmp_path, capsys):
    folder, frames, masks = synthetic_folder
    mp4 = write_mp4(tmp_path / "syn.mp4", frames, fps=30, quality=12)
    r = run_inprocess(capsys, "video", "add", str(folder), "--name", "syn", "-q")
    assert r.code == 0, r.err
    r = run_inprocess(capsys, "video", "add", str(mp4), "--masks", str(folder / "Annotations"), "--json")
    assert r.code == 2 and "already in the store" in r.err  # the default name is the file's stem
    r = run_inprocess(
        capsys,
        "video",
        "add",
        str(mp4),
        "--name",
        "syn-mp4",
        "--masks",
        str(folder / "Annotations"),
        "--json",
    )
    assert r.code == 0, r.err
    assert r.json()["source"]["kind"] == "file" and r.json()["segmenter"] == "masks"
    r = run_inprocess(
        capsys, "video", "add", str(mp4), "--name", "auto", "--box", "21,29,43,39", "--fps", "15", "-q"
    )
    assert r.code == 0, r.err
    r = run_inprocess(capsys, "video", "list", "--json")
    rows = {row["name"]: row for row in r.json()}
    assert (
        set(rows) == {"syn", "syn-mp4", "auto"}
        and rows["auto"]["frames"] == 3
        and rows["auto"]["segmenter"] == "animalnet"
    )
    preview = tmp_path / "prev.mp4"
    r = run_inprocess(capsys, "video", "show", "syn", "--preview", str(preview), "--json")
    assert r.code == 0, r.err
    info = r.json()
    assert len(info["mask_coverage"]) == 6 and info["flow"]["mean_magnitude"] > 0.5
    assert probe_codec(preview) == "h264"
    r = run_inprocess(capsys, "video", "show", "syn")
    assert r.code == 0 and "coverage" in r.out and "flow" in r.out
    for what, count in (("frames", 6), ("masks", 6), ("flow", 2 + 10)):
        out = tmp_path / what
        r = run_inprocess(capsys, "video", "export", "syn", "--what", what, "-o", str(out))
        assert r.code == 0 and len([p for p in out.rglob("*") if p.is_file()]) == count, (what, r.err)
    exported = np.asarray(Image.open(tmp_path / "masks" / "00003.png")) > 127
    assert np.array_equal(exported, masks[3])
    assert np.load(tmp_path / "flow" / "forward.npy").shape == (5, 96, 128, 2)
    r = run_inprocess(capsys, "video", "rm", "auto")
    assert r.code == 0
    r = run_inprocess(capsys, "video", "list")
    assert "2 videos" in r.out


@pytest.mark.parametrize(
    "args, message",
    [
        (["video", "show", "nope"], "no video named"),
        (["video", "add", "/nonexistent/x.mp4"], "does not exist"),
        (["video", "add", "VIDEO", "--box", "1,2,3"], "is not x,y,w,h"),
        (["video", "add", "VIDEO", "--segmenter", "sam"], "no segmenter named"),
        (["video", "add", "VIDEO", "--segmenter", "onnx"], "needs a model"),
        (["video", "export", "nope", "--what", "frames", "-o", "x"], "no video named"),
    ],
)
def test_cli_errors_are_one_line_exit_2(store, synthetic_folder, capsys, args, message):
    folder, _, _ = synthetic_folder
    args = [str(folder / "JPEGImages") if a == "VIDEO" else a for a in args]
    r = run_inprocess(capsys, *args)
    assert r.code == 2 and message in r.err and "Traceback" not in r.err, r.err


@needs_shared_videos
@pytest.mark.slow
def test_davis_sequences_enter_the_store_as_folders_and_mp4(store, tmp_path, capsys):
    """The issue's "done when": each shared DAVIS sequence, as a folder with masks and as an .mp4 made from it."""
    vs = VideoStore.open(store)
    for seq in ("blackswan", "dog", "cows"):
        folder = VIDEOS_DIR / seq
        r = run_inprocess(capsys, "video", "add", str(folder), "--max-size", "256", "--max-frames", "8", "-q")
        assert r.code == 0, r.err
        frames = vs.get(seq, what=("frames",)).frames
        files = sorted((folder / "JPEGImages").glob("*.jpg"))[:8]
        mp4 = write_mp4(
            tmp_path / f"{seq}.mp4", [np.asarray(Image.open(f)) for f in files], fps=24, quality=18
        )
        add_mp4 = ["video", "add", str(mp4), "--name", f"{seq}-mp4", "--max-size", "256", "-q", "--masks"]
        # all 50+ annotations for an 8-frame clip: more masks than frames is an error
        r = run_inprocess(capsys, *add_mp4, str(folder / "Annotations"))
        assert r.code == 2 and "masks in" in r.err and "for a video of 8 frames" in r.err, r.err
        first8 = tmp_path / f"{seq}-masks"
        first8.mkdir()
        for f in sorted((folder / "Annotations").glob("*.png"))[:8]:
            (first8 / f.name).write_bytes(f.read_bytes())
        r = run_inprocess(capsys, *add_mp4, str(first8))
        assert r.code == 0, r.err
        a, b = vs.get(seq, what=("frames", "masks")), vs.get(f"{seq}-mp4", what=("frames", "masks"))
        assert a.frames.shape == b.frames.shape == (8, 144, 256, 3)
        assert (
            np.abs(a.frames.astype(int) - b.frames.astype(int)).mean() < 8 and frames.shape == a.frames.shape
        )
        assert np.array_equal(a.masks, b.masks)  # the same 8 annotation files
        validate(describe_h5(vs.path(f"{seq}-mp4")), "video_h5.schema.json")
