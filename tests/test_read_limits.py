"""Files that would block zooctl or make it allocate without end: a FIFO, a socket or a device
given as a model, video, mask or config; a sparse file or an HDF5 file declaring huge shapes; a
non-finite --wait. Each is one clear line before anything is read.

The bombs run in a child process with a capped address space and a time limit, so a regression
is a failed test (a MemoryError, a hang), never a machine out of memory.
"""

from __future__ import annotations

import json
import os
import resource
import socket
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from cli_helpers import REPO, Result, run_inprocess
from gltf_builder import tiny_gltf, write_tiny_glb
from video_helpers import stored_masked_video

RUN_S = 60
CAP_BYTES = 3 * 1024**3  # a bomb read whole is far over this; zooctl itself runs well under it


def _cap() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (CAP_BYTES, CAP_BYTES))


def run_capped(argv: list[str], env: dict | None = None, timeout: float = RUN_S) -> Result:
    e = {**os.environ, "PYTHONPATH": str(REPO), "NO_COLOR": "1", "COLUMNS": "200", "ZOOCTL_VIEWS": "0"}
    e.pop("ZOOCTL_DEBUG", None)
    e.update(env or {})
    try:
        p = subprocess.run(
            [sys.executable, *argv],
            capture_output=True,
            text=True,
            env=e,
            cwd=REPO,
            timeout=timeout,
            preexec_fn=_cap,
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"{argv} still ran after {timeout} s (blocked on a file?)")
    return Result(p.returncode, p.stdout, p.stderr)


def zooctl(store: Path, *args: str, env: dict | None = None) -> Result:
    return run_capped(["-m", "zooctl", "--store", str(store), *args], env)


def one_clear_line(r: Result, *texts: str, code: int = 2) -> None:
    assert r.code == code and "Traceback" not in r.err and "internal failure" not in r.err, r.err
    lines = r.err.strip().splitlines()
    assert lines[0].startswith("error:") and all(t in lines[0] for t in texts), r.err
    assert len(lines) <= 2, r.err  # the error and its hint


# -- special files ------------------------------------------------------------------------------


def _fifo(p: Path) -> Path:
    os.mkfifo(p)
    return p


def _socket(p: Path) -> Path:
    s = socket.socket(socket.AF_UNIX)
    s.bind(str(p))
    s.close()  # the socket file stays
    return p


def _dev_zero(p: Path) -> Path:
    p.symlink_to("/dev/zero")
    return p


SPECIAL = {
    "fifo": (_fifo, "a FIFO"),
    "socket": (_socket, "a socket"),
    "dev_zero": (_dev_zero, "a character device"),
}


@pytest.mark.parametrize("kind", sorted(SPECIAL))
def test_a_special_file_as_a_model_is_refused(tmp_path, kind):
    make, words = SPECIAL[kind]
    model = make(tmp_path / "m.glb")
    r = zooctl(tmp_path / "store", "bank", "add", str(model), "--no-views")
    one_clear_line(r, "m.glb", words, "not a regular file")


def test_a_gltf_buffer_that_is_a_fifo_or_device_is_refused(tmp_path):
    doc, _ = tiny_gltf()
    for name, make in (
        ("pipe.bin", _fifo),
        ("zero.bin", lambda p: os.mknod(p, 0o600 | 0o020000, os.makedev(1, 5))),
    ):
        folder = tmp_path / name
        folder.mkdir()
        try:
            make(folder / name)
        except PermissionError:  # mknod of a device needs root
            continue
        doc["buffers"][0]["uri"] = name
        (folder / "m.gltf").write_text(json.dumps(doc))
        r = zooctl(tmp_path / "store", "bank", "add", str(folder / "m.gltf"), "--no-views")
        one_clear_line(r, f"refers to {name!r}", "not a regular file")


LIBRARY_CALL = """
import sys
from pathlib import Path
from zooctl.errors import ZooctlError
try:
    {call}
except ZooctlError as e:
    print("error:", e.message, file=sys.stderr)
    sys.exit(e.exit_code)
"""


def library_call(call: str) -> Result:
    """Run one library call in a capped child; its ZooctlError comes back as the CLI prints it."""
    return run_capped(["-c", LIBRARY_CALL.format(call=call)])


def test_a_fifo_as_config_or_video_is_refused(tmp_path):
    fifo = _fifo(tmp_path / "c.json")
    r = library_call(f"from zooctl.fit.config import load_config; load_config(Path({str(fifo)!r}))")
    one_clear_line(r, "config file", "c.json is a FIFO")
    video = _fifo(tmp_path / "v.mp4")
    one_clear_line(
        zooctl(tmp_path / "store", "video", "add", str(video)), "v.mp4", "a FIFO", "not a regular file"
    )
    image = _fifo(tmp_path / "frame.png")
    one_clear_line(zooctl(tmp_path / "store", "video", "add", str(image)), "frame.png", "a FIFO")


def test_a_stored_record_or_config_that_is_a_fifo_is_refused(tmp_path):
    store = tmp_path / "store"
    (store / "fits" / "x").mkdir(parents=True)
    _fifo(store / "fits" / "x" / "record.json")
    one_clear_line(zooctl(store, "fits", "show", "x"), "record of fit 'x'", "a FIFO", code=1)
    prior = tmp_path / "prior"
    prior.mkdir()
    _fifo(prior / "config.json")
    load = f"from zooctl.store.motion_store import load_prior_dir; load_prior_dir(Path({str(prior)!r}))"
    one_clear_line(library_call(load), "holds no readable motion prior", "a FIFO", code=1)
    (prior / "config.json").unlink()
    (prior / "config.json").write_text(json.dumps({"plugin": "pca", "model": {}}))
    _fifo(prior / "pca.npz")  # the PCA prior's weights
    one_clear_line(library_call(load), "pca.npz is a FIFO", code=1)
    cache = store / "videos" / "v.cache"
    cache.mkdir(parents=True)
    _fifo(cache / "query-k4-s128.npz")  # a FIFO as `bank search`'s query cache: a cache miss
    call = f"from zooctl.retrieval.query_cache import read_cache; from zooctl.store.videos import VideoStore; print(read_cache(VideoStore.open({str(store)!r}), 'v', 4, 128))"
    r = library_call(call)
    assert (r.code, r.out) == (0, "None\n"), r


def test_a_fifo_as_mask_source_is_refused(tmp_path):
    from zooctl.errors import InputError
    from zooctl.video.segment import MaskSegmenter

    with pytest.raises(InputError, match="masks.mp4 is a FIFO .named pipe., not a regular file"):
        MaskSegmenter(_fifo(tmp_path / "masks.mp4")).segment(np.zeros((2, 8, 8, 3), np.uint8))


# -- sizes declared in files ---------------------------------------------------------------------


def test_a_sparse_model_file_is_refused_unread(tmp_path):
    big = tmp_path / "big.glb"
    with open(big, "wb") as f:
        f.truncate(16 * 1024**3)  # sparse: takes no disk
    one_clear_line(
        zooctl(tmp_path / "store", "bank", "add", str(big), "--no-views"), "big.glb", "over the read limit"
    )


@pytest.mark.parametrize("how", ["sparse_file", "declared_length"])
def test_a_huge_gltf_buffer_is_refused_unread(tmp_path, how):
    doc, binary = tiny_gltf()
    (tmp_path / "m.bin").write_bytes(binary)
    if how == "sparse_file":  # the file the URI names is 16 GB (of holes)
        with open(tmp_path / "m.bin", "r+b") as f:
            f.truncate(16 * 1024**3)
    else:  # the buffer claims a terabyte
        doc["buffers"][0]["byteLength"] = 2**40
    doc["buffers"][0]["uri"] = "m.bin"
    (tmp_path / "m.gltf").write_text(json.dumps(doc))
    r = zooctl(tmp_path / "store", "bank", "add", str(tmp_path / "m.gltf"), "--no-views")
    one_clear_line(r, "buffer 0", "over the read limit")


def test_a_raised_file_limit_lets_a_big_file_through(tmp_path, monkeypatch):
    """The limit is a limit, not a ban: the error names the variable, and raising it works."""
    from zooctl.errors import InputError
    from zooctl.io.gltf_import import load_gltf

    glb = write_tiny_glb(tmp_path / "t.glb")
    monkeypatch.setenv("ZOOCTL_MAX_FILE_MB", str(glb.stat().st_size / 2**20 / 2))
    with pytest.raises(InputError, match="over the read limit") as exc:
        load_gltf(glb, "t")
    assert "ZOOCTL_MAX_FILE_MB=" in exc.value.hint
    monkeypatch.setenv("ZOOCTL_MAX_FILE_MB", "1")
    assert load_gltf(glb, "t").num_vertices == 4
    monkeypatch.setenv("ZOOCTL_MAX_FILE_MB", "nan")
    with pytest.raises(InputError, match="ZOOCTL_MAX_FILE_MB='nan' is not a positive number"):
        load_gltf(glb, "t")


@pytest.fixture
def bank_store(tmp_path) -> Path:
    store = tmp_path / "store"
    glb = write_tiny_glb(tmp_path / "t.glb")
    assert zooctl(store, "bank", "add", str(glb), "--name", "a", "--no-views").code == 0
    return store


def _replace_dataset(path: Path, key: str, **kw) -> None:
    with h5py.File(path, "r+") as f:
        del f[key]
        f.create_dataset(key, **kw)


def test_an_asset_file_declaring_huge_vertices_is_refused(bank_store, tmp_path):
    h5 = bank_store / "bank" / "assets" / "a.h5"
    _replace_dataset(h5, "mesh/vertices", shape=(300_000_000, 3), dtype="f4", chunks=(4096, 3))
    assert h5.stat().st_size < 100_000  # the shape is declared, not stored
    r = zooctl(bank_store, "bank", "export", "a", "-o", str(tmp_path / "out.glb"))
    one_clear_line(r, "a.h5 declares arrays of 3,433", "over the read limit", code=1)


def test_an_asset_dataset_stored_in_another_file_is_refused(bank_store, tmp_path):
    """HDF5 external storage would read any file (here /etc/passwd) as the asset's vertices."""
    h5 = bank_store / "bank" / "assets" / "a.h5"
    _replace_dataset(h5, "mesh/vertices", shape=(4, 3), dtype="f4", external=[("/etc/passwd", 0, 48)])
    r = zooctl(bank_store, "bank", "export", "a", "-o", str(tmp_path / "out.glb"))
    one_clear_line(r, "mesh/vertices keeps its data in other files", code=1)


def test_an_asset_file_that_is_a_fifo_is_refused(bank_store, tmp_path):
    h5 = bank_store / "bank" / "assets" / "a.h5"
    h5.unlink()
    os.mkfifo(h5)
    r = zooctl(bank_store, "bank", "export", "a", "-o", str(tmp_path / "out.glb"))
    one_clear_line(r, "a.h5 is a FIFO", code=1)


def test_a_video_file_declaring_huge_masks_is_refused(tmp_path):
    root, _ = stored_masked_video(tmp_path, "clip")
    h5 = root / "videos" / "clip.h5"
    _replace_dataset(h5, "masks", shape=(20000, 480, 854), dtype="u1", chunks=(1, 480, 854))
    r = library_call(
        f"from zooctl.store.videos import VideoStore; VideoStore.open({str(root)!r}).get('clip')"
    )
    one_clear_line(r, "clip.h5 declares arrays of 7,8", "over the read limit", code=1)
    # the limit is on what one read takes: the frames alone are still there to read
    frames = f"from zooctl.store.videos import VideoStore; print(len(VideoStore.open({str(root)!r}).get('clip', ('frames',)).frames))"
    assert library_call(frames).out == "6\n"


def test_a_sparse_index_is_refused_and_repair_rebuilds_it(bank_store):
    index = bank_store / "bank" / "index.json"
    with open(index, "r+b") as f:
        f.truncate(4 * 1024**3)
    one_clear_line(zooctl(bank_store, "bank", "list"), "index.json", "over the read limit", code=1)
    r = zooctl(bank_store, "bank", "repair")
    assert r.code == 0, r.err
    assert index.stat().st_size < 10_000
    assert [a["name"] for a in zooctl(bank_store, "bank", "list", "--json").json()] == ["a"]


def test_a_4k_mask_video_is_read_one_frame_at_a_time(tmp_path):
    """24 4K mask frames are 600 MB as RGB (and were stacked once more); read one at a time, only
    their masks at the stored size stay."""
    import imageio_ffmpeg

    video = tmp_path / "masks.mp4"
    ffmpeg = imageio_ffmpeg.get_ffmpeg_exe()
    src = "color=black:s=3840x2160:r=30,drawbox=x=960:y=540:w=1920:h=1080:color=white:t=fill"
    cmd = [ffmpeg, "-v", "error", "-f", "lavfi", "-i", src, "-frames:v", "24"]
    subprocess.run(
        [*cmd, "-c:v", "libx264", "-preset", "ultrafast", "-pix_fmt", "yuv420p", str(video)], check=True
    )
    probe = f"""
import json, numpy as np
from pathlib import Path
from zooctl.video.segment import MaskSegmenter
m = MaskSegmenter(Path({str(video)!r}), original_size=(3840, 2160)).segment(np.zeros((24, 240, 426, 3), np.uint8))
want = np.zeros((240, 426), bool)
want[60:180, 106:320] = True
peak = [ln for ln in open("/proc/self/status") if ln.startswith("VmHWM")][0].split()[1]
print(json.dumps({{"shape": m.shape, "agree": float((m == want).mean()), "peak_kb": int(peak)}}))
"""
    r = run_capped(["-c", probe], timeout=300)  # decoding 4K frames: slow on a busy 2-core machine
    assert r.code == 0, r.err
    got = json.loads(r.out)
    assert got["shape"] == [24, 240, 426] and got["agree"] > 0.99, got
    assert got["peak_kb"] < 500 * 1024, f"peak {got['peak_kb'] / 1024:.0f} MB reading 24 4K mask frames"


# -- waiting ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "-1"])
def test_a_wait_that_is_not_a_finite_number_is_refused(capsys, tmp_path, value):
    r = run_inprocess(capsys, "--store", str(tmp_path / "s"), "--wait", value, "bank", "list")
    assert r.code == 2 and r.err.startswith(f"error: --wait {value} is not a number of seconds"), r.err
    assert len(r.err.strip().splitlines()) == 2


def test_a_lock_timeout_variable_that_is_nan_is_refused(tmp_path):
    glb = write_tiny_glb(tmp_path / "t.glb")
    r = zooctl(tmp_path / "store", "bank", "add", str(glb), "--no-views", env={"ZOOCTL_LOCK_TIMEOUT": "nan"})
    one_clear_line(r, "ZOOCTL_LOCK_TIMEOUT=nan is not a number of seconds")
