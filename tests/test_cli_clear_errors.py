"""Bad outputs, full disks, damaged stored files and bad values: one clear line and a non-zero
exit, never a Python exception, and nothing written where it was not asked for."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings
from pathlib import Path

import h5py
import pytest
from cli_helpers import REPO, Result, run_inprocess
from gltf_builder import write_tiny_glb
from video_helpers import synthetic_video

from zooctl.io.gltf_import import load_gltf
from zooctl.store.bank import Bank
from zooctl.store.videos import VideoStore


def cli(store: Path, *args: str, ulimit_kb: int | None = None, env: dict | None = None) -> Result:
    """The real CLI in a subprocess; ``ulimit_kb``: a full disk, in effect (writes past it fail)."""
    cmd = [sys.executable, "-m", "zooctl", "--store", str(store), *args]
    if ulimit_kb is not None:
        cmd = ["bash", "-c", f'ulimit -f {ulimit_kb}; exec "$@"', "bash", *cmd]
    e = {**os.environ, "PYTHONPATH": str(REPO), "NO_COLOR": "1", "COLUMNS": "200", **(env or {})}
    p = subprocess.run(cmd, capture_output=True, text=True, env=e, cwd=REPO, timeout=300)
    return Result(p.returncode, p.stdout, p.stderr)


def one_clear_line(r: Result, text: str, code: int | None = None) -> None:
    """An error line naming ``text`` (and at most a hint), a non-zero exit, no exception."""
    assert r.code != 0 and "Traceback" not in r.err and "internal failure" not in r.err, r.err
    if code is not None:
        assert r.code == code, (r.code, r.err)
    lines = r.err.strip().splitlines()
    first = next((i for i, line in enumerate(lines) if line.startswith("error:")), None)
    assert first is not None and text in lines[first], r.err
    assert len(lines) - first <= 2, r.err  # the error and its hint, after any progress


@pytest.fixture
def video_store(tmp_path) -> Path:
    root = tmp_path / "store"
    VideoStore.open(root).add(synthetic_video("v"))
    return root


# -- video export ----------------------------------------------------------------------------------


def test_video_export_into_a_file_or_a_device_is_refused(video_store, tmp_path, capsys):
    a_file = tmp_path / "taken"
    a_file.write_bytes(b"keep")
    for out in (a_file, Path("/dev/full")):
        r = run_inprocess(capsys, "--store", str(video_store), "video", "export", "v", "-o", str(out))
        one_clear_line(r, "not a folder", code=2)
    assert a_file.read_bytes() == b"keep"


@pytest.mark.parametrize("what", ["frames", "masks", "flow"])
def test_video_export_on_a_full_disk_is_one_clear_line(video_store, tmp_path, what):
    out = tmp_path / "out"
    r = cli(video_store, "video", "export", "v", "--what", what, "-o", str(out), ulimit_kb=0)
    one_clear_line(r, "no space left on device / file too large")
    assert not [p for p in out.rglob("*") if p.name.endswith(".tmp")]  # no temporaries left


# -- motion train ----------------------------------------------------------------------------------


def test_motion_train_on_a_full_disk_is_one_clear_line(tmp_path):
    store = tmp_path / "store"
    Bank(store).add(load_gltf(write_tiny_glb(tmp_path / "t.glb"), "t"))
    args = ("motion", "train", "--all", "--max-steps", "1", "--width", "8", "--layers", "1")
    r = cli(store, *args, ulimit_kb=8)
    one_clear_line(r, "no space left on device / file too large")
    assert not (store / "motion").exists() or not [
        p for p in (store / "motion").iterdir() if not p.name.startswith(".")
    ]


# -- fits list / show ------------------------------------------------------------------------------

DAMAGED_RECORDS = [
    ("a list", b"[1, 2]"),
    ("a string", b'"x"'),
    ("no name", b'{"status": "done"}'),
    ("another name", b'{"name": "g", "status": "done"}'),
    ("metrics a list", b'{"name": "f", "metrics": [1]}'),
    ("iou a string", b'{"name": "f", "metrics": {"mask_iou": "high"}}'),
    ("outputs a string", b'{"name": "f", "outputs": "x"}'),
    ("frames a table", b'{"name": "f", "frames": {"a": 1}}'),
    ("not utf-8", b"\xff\xfe{"),
    ("not json", b'{"name": "f", '),
]


@pytest.mark.parametrize("content", [c for _, c in DAMAGED_RECORDS], ids=[n for n, _ in DAMAGED_RECORDS])
def test_a_damaged_fit_record_is_one_clear_line(tmp_path, capsys, content):
    store = tmp_path / "store"
    good = {"name": "ok", "status": "done", "template": "t", "frames": 3, "metrics": {"mask_iou": 0.5}}
    for name, data in (("f", content), ("ok", json.dumps(good).encode())):
        (store / "fits" / name).mkdir(parents=True)
        (store / "fits" / name / "record.json").write_bytes(data)
    r = run_inprocess(capsys, "--store", str(store), "fits", "show", "f")
    one_clear_line(r, "the record of fit 'f' is damaged")
    assert "zooctl fits rm f" in r.err
    r = run_inprocess(capsys, "--store", str(store), "fits", "list")
    assert r.code == 0 and "ok" in r.out and "0.500" in r.out, r.err
    assert "skipped f" in r.err and "Traceback" not in r.err, r.err
    r = run_inprocess(capsys, "--store", str(store), "fits", "list", "--json")
    assert r.code == 0 and [x["name"] for x in r.json()] == ["ok"], r.err


# -- bank search of a video with fewer masks than frames --------------------------------------------


def test_bank_search_of_a_stored_video_with_fewer_masks_than_frames(video_store, tmp_path, capsys):
    bank = Bank(video_store)
    bank.add(load_gltf(write_tiny_glb(tmp_path / "t.glb"), "a"))
    path = VideoStore(video_store).path("v")
    with h5py.File(path, "r+") as f:
        masks = f["masks"][()]
        del f["masks"]
        f.create_dataset("masks", data=masks[:2])
    r = run_inprocess(capsys, "--store", str(video_store), "bank", "search", "v", "--embedder", "silhouette")
    one_clear_line(r, "masks")
    assert "zooctl video rm" in r.err


# -- damaged bank assets: render and export refuse them alike ---------------------------------------


def _damage(path: Path, how: str) -> None:
    with h5py.File(path, "r+") as f:
        if how == "2-D vertices":
            v = f["mesh/vertices"][()]
            del f["mesh/vertices"]
            f.create_dataset("mesh/vertices", data=v[:, :2])
        else:
            j = f["skin/joints"][()]
            j[0, 0] = 99
            f["skin/joints"][...] = j


@pytest.mark.parametrize("how", ["2-D vertices", "joint index out of range"])
def test_bank_render_and_export_refuse_a_damaged_asset_alike(tmp_path, capsys, how):
    store = tmp_path / "store"
    bank = Bank(store)
    bank.add(load_gltf(write_tiny_glb(tmp_path / "t.glb"), "a"))
    _damage(bank.asset_path("a"), how)
    errors = []
    for args in (
        ["bank", "render", "a", "-o", str(tmp_path / "a.png")],
        ["bank", "render", "--sheet", "-o", str(tmp_path / "sheet.png")],
        ["bank", "export", "a", "-o", str(tmp_path / "a.usda")],
        ["bank", "export", "a", "-o", str(tmp_path / "a.glb")],
    ):
        r = run_inprocess(capsys, "--store", str(store), *args)
        one_clear_line(r, "asset 'a' in the bank is damaged")
        errors.append(r.err)
    assert len(set(errors)) == 1  # one validation, one message
    assert not list(tmp_path.glob("*.png")) and not (tmp_path / "a.usda").exists()


# -- bank export to a device ------------------------------------------------------------------------


@pytest.mark.parametrize("out", ["/dev/full", "/dev/null"])
def test_bank_export_to_a_device_is_refused(tmp_path, capsys, out):
    store = tmp_path / "store"
    Bank(store).add(load_gltf(write_tiny_glb(tmp_path / "t.glb"), "a"))
    before = set(os.listdir("/dev"))
    r = run_inprocess(capsys, "--store", str(store), "bank", "export", "a", "-o", out)
    one_clear_line(r, "not a regular file", code=2)
    assert set(os.listdir("/dev")) == before  # no /dev/full.usdz


def test_bank_export_to_a_full_disk_is_one_clear_line(tmp_path):
    store = tmp_path / "store"
    Bank(store).add(load_gltf(write_tiny_glb(tmp_path / "t.glb"), "a"))
    r = cli(store, "bank", "export", "a", "-o", str(tmp_path / "a.usda"), ulimit_kb=1)
    one_clear_line(r, "cannot write")


# -- fit --iters 0 ----------------------------------------------------------------------------------


def test_fit_with_zero_iterations_is_refused(tmp_path, capsys):
    r = run_inprocess(
        capsys, "--store", str(tmp_path / "store"), "fit", str(tmp_path / "none.mp4"), "--iters", "0"
    )
    one_clear_line(r, "--iters", code=2)
    assert not (tmp_path / "store" / "fits").exists()


# -- a fit the bank cannot serve ----------------------------------------------------------------------


@pytest.mark.parametrize("batch", [False, True])
@pytest.mark.parametrize("template", [None, "Nope"])
def test_a_fit_the_bank_cannot_serve_stops_before_the_video_is_read(tmp_path, capsys, template, batch):
    """An empty bank, or a template it lacks, is said before decoding, flow and masks (minutes on
    a long clip): the video store stays empty."""
    import cv2
    import numpy as np

    root = tmp_path / "store"
    if template is not None:
        Bank(root).add(load_gltf(write_tiny_glb(tmp_path / "a.glb"), "a"))
    clip = tmp_path / "clip.mp4"
    w = cv2.VideoWriter(str(clip), cv2.VideoWriter_fourcc(*"mp4v"), 10, (64, 48))
    for i in range(4):
        frame = np.zeros((48, 64, 3), np.uint8)
        frame[10:30, 8 + 4 * i : 40 + 4 * i] = 200
        w.write(frame)
    w.release()
    args = ["--store", str(root), "fit", str(clip)] + ([str(clip), "--executor", "local"] if batch else [])
    r = run_inprocess(capsys, *args, *(["--template", template] if template else []))
    one_clear_line(r, "no asset named 'Nope'" if template else "the bank is empty", code=2)
    assert not (root / "videos").exists() or not list((root / "videos").glob("*.h5"))


# -- repair output ----------------------------------------------------------------------------------


def test_repair_prints_no_raw_markup(tmp_path, capsys):
    store = tmp_path / "store"
    bank = Bank(store)
    for n in ("a", "b"):
        bank.add(load_gltf(write_tiny_glb(tmp_path / f"{n}.glb"), n))
    bank.asset_path("b").unlink()  # indexed, but its file is gone: repair drops it
    r = run_inprocess(capsys, "--store", str(store), "bank", "repair")
    assert r.code == 0, r.err
    assert "dropped from the index" in r.err and "[/" not in r.err and "[yellow]" not in r.err, r.err
    assert "b" in r.err
    vs = VideoStore.open(store)
    for n in ("v", "w"):
        vs.add(synthetic_video(n))
    vs.path("w").unlink()
    r = run_inprocess(capsys, "--store", str(store), "video", "repair")
    assert r.code == 0 and "dropped from the index" in r.err and "[/" not in r.err, r.err


# -- USD reference cycles ---------------------------------------------------------------------------


def test_a_usd_reference_cycle_is_one_line(tmp_path, capsys):
    for me, other in (("a", "b"), ("b", "a")):
        (tmp_path / f"{me}.usda").write_text(
            f'#usda 1.0\n(\n    defaultPrim = "Root"\n)\n'
            f'def Xform "Root" (\n    references = @./{other}.usda@</Root>\n)\n{{\n}}\n'
        )
    r = run_inprocess(
        capsys, "--store", str(tmp_path / "store"), "bank", "add", str(tmp_path / "a.usda"), "--no-views"
    )
    one_clear_line(r, "cycle")
    assert "a.usda -> b.usda -> a.usda" in r.err, r.err


# -- huge PNG frames ---------------------------------------------------------------------------------


def _huge_png(path: Path, w: int, h: int) -> None:
    """A valid PNG of w x h black pixels, small on disk (h a multiple of 500)."""
    import struct
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    comp = zlib.compressobj(1)
    rows = b"\0" * ((w + 1) * 500)  # 500 rows: a filter byte and w grey pixels each
    idat = b"".join(comp.compress(rows) for _ in range(h // 500)) + comp.flush()
    ihdr = struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat) + chunk(b"IEND", b""))


@pytest.mark.parametrize("side", [12_000, 14_000])  # PIL warns over 89 MP and refuses over 179 MP
def test_huge_png_frames_are_refused_by_our_limit_without_pil_warnings(tmp_path, capsys, side):
    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(2):
        _huge_png(folder / f"{i:05d}.png", side, side)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # PIL's DecompressionBombWarning would fail the test
        r = run_inprocess(capsys, "--store", str(tmp_path / "store"), "video", "add", str(folder), "-q")
    one_clear_line(r, "over the limit of 120 megapixels", code=2)
    assert "megapixels" in r.err.splitlines()[0]
    assert "DecompressionBomb" not in r.err and "decompression bomb" not in r.err, r.err


def test_an_image_under_our_limit_opens_without_pils_warning(tmp_path):
    """100 MP: over PIL's warning threshold (89 MP), under ours; only the header is read."""
    from zooctl.video.images import open_image

    _huge_png(tmp_path / "big.png", 10_000, 10_000)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with open_image(tmp_path / "big.png") as im:
            assert im.size == (10_000, 10_000)


def test_an_end_of_file_inside_a_command_is_said_not_aborted(tmp_path, monkeypatch, capsys):
    """Click prints only "Aborted!" for an EOFError (np.load of an emptied file raises one): zooctl
    says what failed, in its own one-line form."""
    from cli_helpers import run_inprocess

    from zooctl.store.bank import Bank

    def ended(self, *a, **k):
        raise EOFError("No data left in file")

    monkeypatch.setattr(Bank, "list", ended)
    monkeypatch.setenv("ZOOCTL_STORE", str(tmp_path / "store"))
    r = run_inprocess(capsys, "bank", "list")
    assert r.code == 1 and "Aborted" not in r.err + r.out
    assert "a file or stream ended early: No data left in file" in r.err


def test_export_to_a_new_folder_named_with_a_slash_makes_it(tmp_path, capsys):
    store = tmp_path / "store"
    Bank(store).add(load_gltf(write_tiny_glb(tmp_path / "t.glb"), "a"))
    out = tmp_path / "new" / "deeper"
    r = run_inprocess(
        capsys, "--store", str(store), "bank", "export", "a", "--format", "usda", "-o", f"{out}/"
    )
    assert r.code == 0, r.err
    assert (out / "a.usda").is_file()
    # without the slash it is a file name whose folder must exist: one clear line, nothing made
    r = run_inprocess(
        capsys, "--store", str(store), "bank", "export", "a", "-o", str(tmp_path / "none" / "a.usda")
    )
    one_clear_line(r, "does not exist", code=2)
    assert not (tmp_path / "none").exists()
    # an unknown asset makes no folder either
    r = run_inprocess(
        capsys, "--store", str(store), "bank", "export", "zz", "--format", "usda", "-o", f"{tmp_path}/x/"
    )
    assert r.code != 0 and not (tmp_path / "x").exists()
