"""The lens a file records (`zooctl.video.lens`): QuickTime metadata as ffmpeg and Apple write it,
Exif in a folder's first image, and nothing (never an error) where a file records none."""

from __future__ import annotations

import math
import struct
import subprocess

import numpy as np
import pytest

from zooctl.video.lens import QUICKTIME_FOCAL_KEY, QUICKTIME_LENS_KEY, focal_pixels, read_lens


def ffmpeg_clip(path, *metadata: str) -> None:
    import imageio_ffmpeg

    cmd = [
        imageio_ffmpeg.get_ffmpeg_exe(),
        "-v",
        "error",
        "-y",
        "-f",
        "lavfi",
        "-i",
        "testsrc=size=64x48:rate=10",
    ]
    cmd += ["-t", "0.5", "-pix_fmt", "yuv420p"]
    if metadata:
        cmd += ["-movflags", "use_metadata_tags"]
    for m in metadata:
        cmd += ["-metadata", m]
    subprocess.run([*cmd, str(path)], check=True)


@pytest.mark.parametrize("suffix", [".mp4", ".mov"])
def test_ffmpeg_written_quicktime_keys_are_read(tmp_path, suffix):
    clip = tmp_path / f"phone{suffix}"
    ffmpeg_clip(clip, f"{QUICKTIME_FOCAL_KEY}=26", f"{QUICKTIME_LENS_KEY}=Back Camera 4.2mm f/1.6")
    assert read_lens(clip) == {
        "focal_35mm": 26.0,
        "lens_model": "Back Camera 4.2mm f/1.6",
        "from": "quicktime",
    }


def test_a_clip_without_a_lens_gives_none(tmp_path):
    clip = tmp_path / "plain.mp4"
    ffmpeg_clip(clip)
    assert read_lens(clip) is None


def box(kind: bytes, payload: bytes, large: bool = False) -> bytes:
    if large:  # a 64-bit size, as writers use for atoms over 4 GB
        return struct.pack(">I4sQ", 1, kind, len(payload) + 16) + payload
    return struct.pack(">I4s", len(payload) + 8, kind) + payload


def quicktime_file(value: bytes, type_code: int, full_box_meta: bool = False) -> bytes:
    """mdat first (moov at the end, as cameras write), QuickTime keys + ilst in moov/meta."""
    keys = [b"mdta" + QUICKTIME_LENS_KEY.encode(), b"mdta" + QUICKTIME_FOCAL_KEY.encode()]
    key_box = box(
        b"keys", struct.pack(">II", 0, len(keys)) + b"".join(struct.pack(">I", len(k) + 4) + k for k in keys)
    )
    data = box(b"data", struct.pack(">II", type_code, 0) + value)
    ilst = box(b"ilst", box(struct.pack(">I", 2), data))
    hdlr = box(b"hdlr", bytes(8) + b"mdta" + bytes(13))
    meta = box(b"meta", (bytes(4) if full_box_meta else b"") + hdlr + key_box + ilst)
    return (
        box(b"ftyp", b"qt  " + bytes(4))
        + box(b"mdat", bytes(1000), large=True)
        + box(b"moov", box(b"udta", meta))
    )


@pytest.mark.parametrize(
    ("value", "type_code"),
    [
        (struct.pack(">f", 28.0), 23),  # big-endian float32
        (struct.pack(">d", 28.0), 24),
        (struct.pack(">h", 28), 21),  # big-endian signed integer
        (b"28", 1),  # UTF-8, as ffmpeg writes it
    ],
)
@pytest.mark.parametrize("full_box_meta", [False, True])
def test_value_types_and_atom_layouts(tmp_path, value, type_code, full_box_meta):
    clip = tmp_path / "cam.mov"
    clip.write_bytes(quicktime_file(value, type_code, full_box_meta))
    assert read_lens(clip) == {"focal_35mm": 28.0, "lens_model": None, "from": "quicktime"}


@pytest.mark.parametrize("cut", [10, 40, 1030, -20])
def test_truncated_or_garbled_files_give_none(tmp_path, cut):
    clip = tmp_path / "cut.mov"
    clip.write_bytes(quicktime_file(struct.pack(">f", 28.0), 23)[:cut])
    assert read_lens(clip) is None
    clip.write_bytes(b"\xff" * 64)
    assert read_lens(clip) is None


@pytest.mark.parametrize("value", [b"0", b"-26", b"nan", b"wide"])
def test_implausible_values_are_ignored(tmp_path, value):
    clip = tmp_path / "odd.mov"
    clip.write_bytes(quicktime_file(value, 1))
    assert read_lens(clip) is None


def test_exif_of_a_folders_first_image(tmp_path):
    from PIL import Image

    (tmp_path / "JPEGImages").mkdir()
    for i in range(3):
        im = Image.fromarray(np.full((24, 32, 3), 40 * i, np.uint8))
        exif = Image.Exif()
        if i == 0:
            exif.get_ifd(0x8769).update({41989: 35, 0xA434: "Zoom 7-21mm"})
        im.save(tmp_path / "JPEGImages" / f"{i:05d}.jpg", exif=exif)
    assert read_lens(tmp_path) == {"focal_35mm": 35.0, "lens_model": "Zoom 7-21mm", "from": "exif"}
    plain = tmp_path / "plain"
    plain.mkdir()
    Image.fromarray(np.zeros((8, 8, 3), np.uint8)).save(plain / "0.png")
    assert read_lens(plain) is None
    assert read_lens(tmp_path / "empty-does-not-exist") is None


def test_focal_pixels_matches_the_diagonal_field_of_view():
    # a 35 mm-equivalent focal gives the diagonal field of view it has on a 36 x 24 mm frame
    for f35, (w, h) in [(26.0, (1920, 1080)), (50.0, (854, 480)), (13.0, (640, 640))]:
        f = focal_pixels(f35, w, h)
        assert math.atan(math.hypot(w, h) / 2 / f) == pytest.approx(math.atan(math.hypot(36, 24) / 2 / f35))
    # 36 mm wide frames: a 36 mm frame's focal in pixels is f35 / 36 x the width
    assert focal_pixels(50.0, 3600, 2400) == pytest.approx(5000.0)


# -- the lens through `video add` and into the fit ----------------------------------------------


@pytest.fixture
def clip(tmp_path):
    """An 8-frame 128x96 clip written by ffmpeg with an iPhone's lens keys, and its masks."""
    import imageio_ffmpeg
    from PIL import Image
    from video_helpers import moving_object_video

    frames, masks = moving_object_video(t=8, h=96, w=128)
    (tmp_path / "png").mkdir()
    (tmp_path / "masks").mkdir()
    for i, (f, m) in enumerate(zip(frames, masks, strict=True)):
        Image.fromarray(f).save(tmp_path / "png" / f"{i:05d}.png")
        Image.fromarray(m.astype(np.uint8) * 255).save(tmp_path / "masks" / f"{i:05d}.png")
    out = tmp_path / "phone.mov"
    cmd = [
        imageio_ffmpeg.get_ffmpeg_exe(),
        "-v",
        "error",
        "-framerate",
        "24",
        "-i",
        str(tmp_path / "png" / "%05d.png"),
    ]
    cmd += ["-pix_fmt", "yuv420p", "-movflags", "use_metadata_tags"]
    cmd += ["-metadata", f"{QUICKTIME_FOCAL_KEY}=26", "-metadata", f"{QUICKTIME_LENS_KEY}=Back Camera"]
    subprocess.run([*cmd, str(out)], check=True)
    return out, tmp_path / "masks", tmp_path / "png"


def test_video_add_stores_the_files_lens_or_the_users(store, clip, capsys):
    import json

    from cli_helpers import run_inprocess

    from zooctl.store.video_reader import StoredVideo
    from zooctl.store.videos import VideoStore

    mov, masks, png = clip
    r = run_inprocess(capsys, "video", "add", str(mov), "--masks", str(masks), "-q", "--json")
    assert r.code == 0, r.err
    lens = {"focal_35mm": 26.0, "lens_model": "Back Camera", "from": "quicktime"}
    assert json.loads(r.out)["source"]["lens"] == lens
    with StoredVideo(VideoStore.open(store).path("phone")) as rec:
        assert rec.source["lens"] == lens
    r = run_inprocess(capsys, "video", "show", "phone")
    assert "lens: 26 mm 35 mm-equivalent, Back Camera (the file's QuickTime metadata)" in r.out
    # --lens: the user's lens instead of the file's; a folder of PNGs records none
    r = run_inprocess(
        capsys, "video", "add", str(mov), "--masks", str(masks), "--name", "b", "--lens", "52", "-q"
    )
    assert r.code == 0, r.err
    assert VideoStore.open(store).summary("b")["source"]["lens"] == {
        "focal_35mm": 52.0,
        "lens_model": None,
        "from": "user",
    }
    r = run_inprocess(capsys, "video", "add", str(png), "--masks", str(masks), "--name", "c", "-q")
    assert r.code == 0 and "lens" not in VideoStore.open(store).summary("c")["source"]


def test_a_lens_out_of_range_is_one_clear_line_and_stores_nothing(store, clip, capsys):
    from cli_helpers import run_inprocess

    mov, masks, _ = clip
    r = run_inprocess(capsys, "video", "add", str(mov), "--masks", str(masks), "--lens", "0", "-q")
    assert r.code != 0 and "Traceback" not in r.err
    assert "--lens 0 is not a 35 mm-equivalent focal length" in r.err
    assert run_inprocess(capsys, "video", "list", "--json").out.strip() == "[]"


def test_where_the_focal_comes_from():
    from zooctl.fit.config import preset
    from zooctl.fit.focal import lens_note, resolve_focal
    from zooctl.fit.inputs import FitVideo

    frames = np.zeros((2, 480, 854, 3), np.uint8)
    video = FitVideo("v", frames, np.ones((2, 480, 854), bool))
    cfg = preset("fast")
    got, focal = resolve_focal(cfg, video)  # nothing known: a normal lens, the frame's diagonal
    assert focal == {"from": "normal", "px": math.hypot(854, 480)} and got.camera.focal == focal["px"]
    cfg.camera.focal_guess = "search"
    assert resolve_focal(cfg, video) == (cfg, {"from": "estimated"})
    video.lens = {"focal_35mm": 26.0, "lens_model": None, "from": "quicktime"}
    got, focal = resolve_focal(cfg, video)
    assert focal["from"] == "lens" and focal["px"] == pytest.approx(focal_pixels(26.0, 854, 480))
    assert got.camera.focal == focal["px"] and cfg.camera.focal is None  # the caller's config is not changed
    assert (
        lens_note(focal)
        == f"focal {focal['px']:.0f} px from the lens: 26 mm 35 mm-equivalent (the file's QuickTime metadata)"
    )
    cfg.camera.lens_35mm = 50.0  # --lens: before the video's own
    got, focal = resolve_focal(cfg, video)
    assert focal["lens"]["from"] == "config" and got.camera.focal == pytest.approx(
        focal_pixels(50.0, 854, 480)
    )
    video.intrinsics = np.array([700.0, 700.0, 427.0, 240.0])  # a benchmark folder's camera:
    assert resolve_focal(cfg, video)[1]["lens"]["from"] == "config"  # after --lens
    cfg.camera.lens_35mm = None
    assert resolve_focal(cfg, video)[1] == {"from": "video", "px": 700.0}  # before a recorded lens
    cfg.camera.focal = 900.0  # --focal: before everything
    assert resolve_focal(cfg, video) == (cfg, {"from": "given", "px": 900.0})
