"""`zooctl view` (plugins/zooctl-viewer) in a real browser: headless Chromium loads the page of a
small fit, from disk (``--export``) and from the server, and its screenshots are checked: the
character is drawn where its silhouette is, moving the slider changes the pose, the skeleton and
the free view draw, and the page reports no errors. Bad input gets one line and a non-zero exit."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
from cli_helpers import REPO, zooctl

pytest.importorskip(
    "zooctl_viewer",
    reason="the zooctl-viewer plugin is not installed (pip install plugins/zooctl-viewer; make test does)",
)

from zooctl_viewer.browser import Chromium, find_chromium  # noqa: E402

needs_chromium = pytest.mark.skipif(
    find_chromium() is None,
    reason="no chromium to test the page in (apt-get install chromium; .ci/run does)",
)
FRAMES = 8
BACKGROUND = (0x2A, 0x2F, 0x36)  # the 3D view's clear colour (fit.js)


@pytest.fixture(scope="module")
def fit(tmp_path_factory):
    """(store, fit record) of a few-second fit of a procedural quadruped's video, given as a DAVIS
    folder so the fit stores it (the path a user's video takes)."""
    from fit_helpers import tiny_fit_config, write_davis_folder

    from zooctl.benchdata.make import make_video
    from zooctl.fit.inputs import load_bench_video
    from zooctl.fit.job import fit_job
    from zooctl.procedural import build_animal
    from zooctl.store.bank import Bank

    root = tmp_path_factory.mktemp("viewer")
    store = root / "store"
    asset = build_animal("quadruped", name="quadruped")
    Bank(store).add(asset)
    bench = load_bench_video(make_video(asset, root / "bench", frames=FRAMES, size=96, seed=5))
    folder = write_davis_folder(root / "walk", bench.frames, bench.masks)
    rec = fit_job(
        str(folder), store, tiny_fit_config(3), name="walk", template="quadruped", outputs=("usd", "glb")
    )
    assert rec["stored_video"] and rec["outputs"]["glb"].endswith(".glb")
    return store, rec


@pytest.fixture(scope="module")
def site(fit, tmp_path_factory):
    store, _ = fit
    out = tmp_path_factory.mktemp("site") / "walk-view"
    r = zooctl("view", "walk", "--export", str(out), store=store)
    assert r.code == 0, r.err
    assert f"wrote {out / 'index.html'}" in " ".join(r.out.split())
    return out


@pytest.fixture(scope="module")
def browser():
    if find_chromium() is None:
        pytest.skip("no chromium to test the page in (apt-get install chromium; .ci/run does)")
    with Chromium(width=1400, height=1000) as b:
        yield b


def test_export_writes_a_self_contained_site(site, fit):
    _, rec = fit
    data = (site / "data.js").read_text()
    assert data.startswith("window.ZOOCTL_VIEW = ")
    d = json.loads(data[len("window.ZOOCTL_VIEW = ") :].rstrip().rstrip(";"))
    assert d["frames"] == FRAMES and len(d["frame_files"]) == FRAMES
    assert all((site / f).is_file() for f in d["frame_files"] + d["overlay_files"])
    assert d["record"]["metrics"]["mask_iou"] == rec["metrics"]["mask_iou"]
    assert d["camera"]["source"] == "walk.usd /World/Camera"
    # The page's own reprojection agrees with the fit's measurement of the same exported mesh.
    shown = np.nanmean([x for x in d["silhouette_iou"] if x is not None])
    assert shown == pytest.approx(rec["metrics"]["mask_iou"], abs=0.02)
    html = (site / "index.html").read_text()
    assert "https://" not in html and "http://" not in html  # nothing from a CDN
    assert (site / "vendor" / "three.LICENSE").read_text().startswith("The MIT License")
    assert "0.187.0" in (site / "vendor" / "VERSION").read_text()


def _drawn(img: np.ndarray) -> np.ndarray:
    """(H, W) bool: pixels of the 3D view that are not its background."""
    return np.abs(img.astype(int) - BACKGROUND).max(-1) > 12


def _silhouette_at(store, rec, frame: int, H: int, W: int, name: str = "walk") -> np.ndarray:
    """The fitted character of ``frame`` rasterised by zooctl through the fit's camera at (H, W)."""
    import torch
    from zooctl_viewer.fit_data import input_camera

    from zooctl.render.camera import Camera
    from zooctl.render.raster import rasterize
    from zooctl.store.fits import FitStore

    h, w = rec["image_size"]
    cam = input_camera(rec, h, w)["torch"]
    s = W / w
    k = cam.intrinsics * torch.tensor([s, H / h, s, H / h])
    cam = Camera(k, cam.rotation, cam.translation, H, W)
    asset = FitStore(store).character(name)
    v = torch.as_tensor(asset.pose("fit", np.array([frame])).astype(np.float32))
    return rasterize(v, torch.as_tensor(asset.faces, dtype=torch.long), cam).mask[0].numpy()


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


def _open(browser, url: str) -> None:
    """Load ``url`` in a clean state: what the previous page still reported is dropped."""
    browser.goto("about:blank")
    browser.evaluate("1")
    browser.events.clear()
    browser.goto(url)
    browser.wait_for("document.body && document.body.dataset.ready === '1'", timeout=60)


def _show(browser, frame: int, view: str = "input") -> np.ndarray:
    browser.evaluate(f"zooctlShow({frame}, '{view}')")
    browser.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))", True)
    return browser.screenshot("#canvas3d")


@needs_chromium
def test_the_character_is_drawn_where_its_silhouette_is(site, fit, browser, tmp_path):
    store, rec = fit
    _open(browser, (site / "index.html").as_uri())
    for frame in (0, FRAMES - 1):
        img = _show(browser, frame)
        drawn = _drawn(img)
        sil = _silhouette_at(store, rec, frame, *drawn.shape)
        iou = _iou(drawn, sil)
        if iou < 0.85:
            from PIL import Image

            Image.fromarray(img).save(tmp_path / f"frame{frame}.png")
        assert iou > 0.85, f"frame {frame}: the page's character covers its silhouette with IoU {iou:.3f}"
        assert drawn.mean() > 0.01  # something, not the background alone
    assert browser.errors() == []


@needs_chromium
def test_the_slider_moves_the_pose(site, fit, browser):
    _open(browser, (site / "index.html").as_uri())
    first = _show(browser, 0)
    # Drag the real slider (mouse events at its right end): the last frame.
    x, y, w, h = browser.evaluate(
        "(() => { const r = document.getElementById('slider').getBoundingClientRect();"
        " return [r.left, r.top, r.width, r.height]; })()"
    )
    for kind in ("mousePressed", "mouseReleased"):
        browser.call(
            "Input.dispatchMouseEvent",
            {"type": kind, "x": x + w - 2, "y": y + h / 2, "button": "left", "clickCount": 1},
        )
    assert browser.evaluate("document.getElementById('slider').value") == str(FRAMES - 1)
    assert (
        browser.evaluate("document.getElementById('frame').getAttribute('src')")
        == f"frames/{FRAMES - 1:05d}.jpg"
    )
    browser.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))", True)
    last = browser.screenshot("#canvas3d")
    changed = _drawn(first) != _drawn(last)
    assert changed.mean() > 0.002, "moving the slider left the character where it was"
    assert browser.errors() == []


@needs_chromium
def test_skeleton_and_free_view(site, browser):
    _open(browser, (site / "index.html").as_uri())
    plain = _show(browser, 0)
    browser.evaluate("document.getElementById('skeleton').click()")
    with_bones = _show(browser, 0)
    assert (np.abs(plain.astype(int) - with_bones).max(-1) > 40).mean() > 0.0005
    browser.evaluate("document.getElementById('skeleton').click()")
    # A drag on the canvas orbits: the view switches to free and shows the character from elsewhere.
    x, y, w, h = browser.evaluate(
        "(() => { const r = document.getElementById('canvas3d').getBoundingClientRect();"
        " return [r.left, r.top, r.width, r.height]; })()"
    )
    cx, cy = x + w / 2, y + h / 2
    browser.call(
        "Input.dispatchMouseEvent",
        {"type": "mousePressed", "x": cx, "y": cy, "button": "left", "clickCount": 1},
    )
    for k in range(1, 11):
        browser.call(
            "Input.dispatchMouseEvent",
            {"type": "mouseMoved", "x": cx + 25 * k, "y": cy, "button": "left", "buttons": 1},
        )
    browser.call(
        "Input.dispatchMouseEvent",
        {"type": "mouseReleased", "x": cx + 250, "y": cy, "button": "left", "clickCount": 1},
    )
    assert browser.evaluate("document.getElementById('view-free').classList.contains('on')")
    browser.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))", True)
    orbited = browser.screenshot("#canvas3d")
    assert _iou(_drawn(orbited), _drawn(plain)) < 0.8 and _drawn(orbited).mean() > 0.005
    # The input-view preset brings the fitted camera back exactly.
    back = _show(browser, 0, "input")
    assert _iou(_drawn(back), _drawn(plain)) > 0.98
    assert browser.errors() == []


@needs_chromium
def test_the_page_reports_what_it_was_measured_against(site, fit, browser):
    _, rec = fit
    _open(browser, (site / "index.html").as_uri())
    text = browser.evaluate("document.getElementById('metrics').innerText")
    assert "mask IoU" in text and f"{rec['metrics']['mask_iou']:.3f}" in text
    assert "against the video's stored masks" in text
    assert "was given (--template)" in browser.evaluate("document.getElementById('template').innerText")


@needs_chromium
def _ctrl_c_default() -> None:
    """The server as a terminal starts it: with Ctrl-C's default. A child inherits an ignored
    SIGINT (some test runners' workers ignore it), and then Python never raises KeyboardInterrupt."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _serve(store, *extra: str) -> subprocess.Popen:
    """`zooctl view walk` serving on a free port, as a terminal starts it; its first line says where."""
    return subprocess.Popen(
        [sys.executable, "-m", "zooctl", "view", "walk", "--no-browser", "--port", "0", *extra],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=dict(os.environ, ZOOCTL_STORE=str(store), COLUMNS="200", NO_COLOR="1"),
        cwd=REPO,
        preexec_fn=_ctrl_c_default,
    )


def test_served_on_localhost_and_stops_on_ctrl_c(fit, browser):
    store, _ = fit
    p = _serve(store)
    try:
        line = p.stdout.readline()
        assert "serving fit walk at http://127.0.0.1:" in line, line + p.stderr.read()
        url = line.split(" at ", 1)[1].split()[0]
        _open(browser, url)
        assert browser.evaluate("window.ZOOCTL_VIEW.name") == "walk"
        assert browser.errors() == []
    finally:
        browser.goto("about:blank")  # before the server stops: the page's loads end with it
        p.send_signal(signal.SIGINT)
        out, err = p.communicate(timeout=30)
    assert p.returncode == 0, err
    assert "Traceback" not in err


def test_exposing_the_server_says_so(fit):
    store, _ = fit
    p = _serve(store, "--host", "0.0.0.0")
    try:
        assert "serving fit walk at http://127.0.0.1:" in p.stdout.readline()
    finally:
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=30)
    assert "warning: serving on 0.0.0.0" in " ".join(err.split())
    assert "anyone who can reach this machine" in " ".join(err.split())


def test_bad_input_gets_one_line(fit, tmp_path):
    store, _ = fit
    r = zooctl("view", "nosuch", "--export", str(tmp_path / "x"), store=store)
    assert r.code != 0 and "Traceback" not in r.err and "nosuch" in r.err
    r = zooctl("view", store=store)
    assert r.code != 0 and "give a FIT to view, or --bank" in r.err
    busy = tmp_path / "busy"
    busy.mkdir()
    (busy / "notes.txt").write_text("mine")
    r = zooctl("view", "walk", "--export", str(busy), store=store)
    assert r.code != 0 and "not empty" in r.err and (busy / "notes.txt").read_text() == "mine"
    assert not (tmp_path / "x").exists()


def test_export_again_replaces_the_earlier_export(fit, site):
    store, _ = fit
    t = time.time()
    r = zooctl("view", "walk", "--export", str(site), store=store)
    assert r.code == 0, r.err
    assert (site / "index.html").stat().st_mtime >= t - 1


@pytest.fixture(scope="module")
def bank_site(tmp_path_factory):
    """A gallery export of a bank of two procedural animals (turntables cached in a private folder)."""
    from zooctl.procedural import build_animal
    from zooctl.store.bank import Bank

    root = tmp_path_factory.mktemp("gallery")
    store = root / "store"
    bank = Bank(store)
    bank.add(build_animal("quadruped", name="quadruped"))
    bank.add(build_animal("bird", name="bird"))
    env = {"ZOOCTL_VIEWER_CACHE": str(root / "cache")}
    r = zooctl("view", "--bank", "--export", str(root / "site"), store=store, env=env)
    assert r.code == 0, r.err
    return store, root / "site", env


def test_bank_gallery_filters_and_plays_an_asset(bank_site, browser):
    _, site, _ = bank_site
    _open(browser, (site / "index.html").as_uri())
    names = browser.evaluate("Array.from(document.querySelectorAll('.tile .name')).map(e => e.textContent)")
    assert sorted(names) == ["bird", "quadruped"]
    assert browser.evaluate("document.getElementById('count').textContent") == "2 of 2 assets"
    # Every turntable is an image of its asset, not a blank.
    tile = browser.screenshot(".tile .turn")
    assert tile.std() > 10
    browser.evaluate("document.querySelector('.tag.chip[data-tag=bird]').click()")
    assert browser.evaluate("document.getElementById('count').textContent") == "1 of 2 assets"
    visible = "Array.from(document.querySelectorAll('.tile')).filter(t => !t.hidden).map(t => t.querySelector('.name').textContent)"
    assert browser.evaluate(visible) == ["bird"]
    browser.evaluate("Array.from(document.querySelectorAll('.tile')).find(t => !t.hidden).click()")
    assert browser.wait_for("document.body.dataset.asset", timeout=30) == "bird"
    clips = browser.evaluate("Array.from(document.getElementById('clip').options).map(o => o.textContent)")
    assert clips and all("(" in c for c in clips)
    browser.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))", True)
    a = browser.screenshot("#canvas3d")
    assert _drawn(a).mean() > 0.005, "the opened asset is not drawn"
    moved = 0.0
    for _ in range(20):  # the clip plays in real time: look again until it has moved (or 5 s)
        time.sleep(0.25)
        moved = (_drawn(a) != _drawn(browser.screenshot("#canvas3d"))).mean()
        if moved > 0.0005:
            break
    assert moved > 0.0005, "the asset's clip does not play"
    assert browser.errors() == []


def test_bank_tag_option_and_cache(bank_site, tmp_path):
    store, _, env = bank_site
    r = zooctl("view", "--bank", "--tag", "bird", "--export", str(tmp_path / "birds"), store=store, env=env)
    assert r.code == 0, r.err
    assert len(list((tmp_path / "birds" / "turntables").iterdir())) == 1
    assert len(list((tmp_path / "birds" / "assets").iterdir())) == 1
    r = zooctl(
        "view", "--bank", "--tag", "nosuchtag", "--export", str(tmp_path / "none"), store=store, env=env
    )
    assert r.code != 0 and "no asset in the bank has the tag nosuchtag" in r.err
    r = zooctl("view", "walk", "--tag", "bird", store=store, env=env)
    assert r.code != 0 and "--tag filters the bank gallery" in r.err


def test_bench_table_opens_each_fit(fit, browser, tmp_path):
    """`bench run`'s fits of a folder (here one 6-frame video, its `full` ablation) as a table;
    its row opens the fit's page (which `bench run` wrote without USD or GLB: the page's camera
    comes from the record, its GLB from the stored character)."""
    from fit_helpers import tiny_overrides

    from zooctl.benchdata.make import make_video
    from zooctl.benchdata.run import run_benchmark
    from zooctl.store.bank import Bank

    store, _ = fit
    folder = tmp_path / "videos"
    make_video(Bank.open(store).get("quadruped"), folder, frames=6, size=48, seed=2)
    run_benchmark(folder, store, ablations=["full"], template="quadruped", overrides=tiny_overrides())
    out = tmp_path / "bench-view"
    r = zooctl("view", "--bench", str(folder), "--export", str(out), store=store)
    assert r.code == 0, r.err
    _open(browser, (out / "index.html").as_uri())
    rows = browser.evaluate("Array.from(document.querySelectorAll('#rows tr.link')).map(r => r.innerText)")
    assert len(rows) == 1 and rows[0].startswith("quadruped\tfull\tquadruped")
    browser.evaluate("document.querySelector('#rows tr.link').click()")
    browser.wait_for("location.href.endsWith('fits/bench-quadruped-full/index.html')", timeout=30)
    browser.wait_for("document.body && document.body.dataset.ready === '1'", timeout=60)
    assert browser.evaluate("window.ZOOCTL_VIEW.camera.source") == "fit record (camera.focal_px)"
    assert _drawn(_show(browser, 0)).mean() > 0.005
    assert browser.errors() == []
    r = zooctl("view", "--bench", str(tmp_path / "nothing"), "--export", str(tmp_path / "x"), store=store)
    assert r.code != 0 and "holds no benchmark videos" in r.err


def test_animate_folder_beside_the_real_clip(fit, browser, tmp_path):
    """`animate`'s samples (a PCA prior: seconds to train) beside the character's own clip."""
    store, _ = fit
    r = zooctl("motion", "train", "--assets", "quadruped", "--kind", "pca", "--name", "pca", store=store)
    assert r.code == 0, r.err
    folder = tmp_path / "anim"
    args = ["animate", "quadruped", "--sample", "2", "--frames", "20", "--prior", "pca", "--no-preview"]
    r = zooctl(*args, "--formats", "glb", "--out", str(folder), store=store)
    assert r.code == 0, r.err
    out = tmp_path / "anim-view"
    r = zooctl("view", "--animate", str(folder), "--export", str(out), store=store)
    assert r.code == 0, r.err
    _open(browser, (out / "index.html").as_uri())
    titles = browser.evaluate(
        "Array.from(document.querySelectorAll('#panels strong')).map(e => e.textContent)"
    )
    assert titles[0].startswith("real: ") and titles[1:] == ["quadruped_sample00", "quadruped_sample01"]
    browser.evaluate("zooctlShow(0.0)")
    browser.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))", True)
    before = [browser.screenshot(f"[data-panel='{i}'] canvas") for i in range(3)]
    assert all(_drawn(b).mean() > 0.005 for b in before), "a panel draws no character"
    browser.evaluate("zooctlShow(0.4)")
    browser.evaluate("new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))", True)
    after = [browser.screenshot(f"[data-panel='{i}'] canvas") for i in range(3)]
    assert all((_drawn(a) != _drawn(b)).mean() > 0.0005 for a, b in zip(after, before, strict=True))
    assert browser.errors() == []
    r = zooctl("view", "--animate", str(tmp_path), "--export", str(tmp_path / "x"), store=store)
    assert r.code != 0 and "holds no animate.json" in r.err


def test_a_browser_that_hangs_up_mid_reply_prints_nothing(tmp_path, capsys):
    """A reload or a closed tab while frames load breaks the connection: http.server printed a
    BrokenPipeError traceback on the user's terminal for each one."""
    import socket
    import struct
    import threading

    from zooctl_viewer.serve import make_server

    (tmp_path / "big.bin").write_bytes(b"x" * 20_000_000)
    server = make_server(tmp_path, "127.0.0.1", 0)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        for _ in range(3):
            s = socket.create_connection(("127.0.0.1", server.server_address[1]))
            s.sendall(b"GET /big.bin HTTP/1.1\r\nHost: x\r\n\r\n")
            s.recv(100)
            s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))  # a reset
            s.close()
        time.sleep(1.0)
    finally:
        server.shutdown()
        server.server_close()
    assert "Traceback" not in capsys.readouterr().err


def test_wait_for_polls_through_navigations(browser, tmp_path):
    """A poll sent while the page is replaced by another (a row's click) is a 'not yet', not an
    error: here a chain of pages, each opening the next at once, is polled without a pause until
    the last one is ready."""
    n = 30
    for i in range(n):
        body = (
            "<script>document.body.dataset.ready = '1'</script>"
            if i == n - 1
            else f"<script>location.replace('p{i + 1}.html')</script>"
        )
        (tmp_path / f"p{i}.html").write_text(f"<!doctype html><html><body>{body}</body></html>")
    browser.goto("about:blank")
    browser.evaluate("1")
    browser.goto((tmp_path / "p0.html").as_uri())
    browser.wait_for("document.body && document.body.dataset.ready === '1'", timeout=30, poll=0)
    assert browser.evaluate("location.href").endswith(f"p{n - 1}.html")
