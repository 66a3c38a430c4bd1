"""`zooctl view` page load: milliseconds from navigation to the first drawn frame (the character
rendered and the first video frame decoded) of a 60-frame fit, from disk (`--export`) and from the
server, in headless Chromium (WebGL on SwiftShader, the CPU); then the playback rate, and the
bank gallery's load with 200 tiles (the starter animals' turntables, repeated).

    .venv/bin/python bench/viewer.py [--frames 60] [--size 240] [--repeat 5] [--tiles 200]
        [--work bench/out/viewer] [--out bench/out/viewer.json]

The fit is a short one (its quality does not matter here), made once in --work and reused.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import REPO, machine, write_json  # noqa: E402

SHORT_FIT = {
    "fit_size": 32,
    "stage1": {"iters": 2, "batch": 4},
    "stage2": {"iters": 2, "batch": 3},
    "camera": {"azimuths": 4, "elevations": [10.0], "search_size": 32},
}


def make_fit(work: Path, frames: int, size: int) -> Path:
    """The store in ``work`` with the fit ``bench`` of a ``frames``-frame video (a DAVIS folder, so
    the fit stores it as a user's video is stored)."""
    from zooctl.benchdata.make import make_video
    from zooctl.fit.config import FitConfig, preset
    from zooctl.fit.inputs import load_bench_video
    from zooctl.fit.job import fit_job
    from zooctl.procedural import build_animal
    from zooctl.store.bank import Bank
    from zooctl.store.fits import FitStore

    store = work / "store"
    fits = FitStore(store)
    if fits.exists("bench") and fits.get("bench").get("frames") == frames:
        return store
    asset = build_animal("quadruped", name="quadruped")
    bank = Bank(store)
    if "quadruped" not in bank:
        bank.add(asset)
    bench = load_bench_video(make_video(asset, work / "bench", frames=frames, size=size, seed=7))
    folder = work / "davis"
    (folder / "JPEGImages").mkdir(parents=True, exist_ok=True)
    (folder / "Annotations").mkdir(exist_ok=True)
    from PIL import Image

    for i, (f, m) in enumerate(zip(bench.frames, bench.masks, strict=True)):
        Image.fromarray(f).save(folder / "JPEGImages" / f"{i:05d}.jpg", quality=95)
        Image.fromarray(m.astype("uint8") * 255).save(folder / "Annotations" / f"{i:05d}.png")
    cfg = FitConfig.from_dict(SHORT_FIT, preset("fast"))
    if fits.exists("bench"):
        fits.remove("bench")
    fit_job(str(folder), store, cfg, name="bench", template="quadruped", outputs=("usd", "glb"))
    return store


MARKS = ("zooctl:scripts-loaded", "zooctl:glb-parsed", "zooctl:first-render")


def first_frame_ms(url: str, play: bool = True, marks: dict | None = None) -> tuple[float, float]:
    """(ms to the first drawn frame, frames shown per second while playing for 2 s, or NaN without
    ``play``) in a new headless Chromium; ``marks`` gets the page's performance marks (ms)."""
    from zooctl_viewer.browser import Chromium

    with Chromium(width=1400, height=1000) as b:
        b.goto(url)
        ms = b.wait_for("window.ZOOCTL_FIRST_FRAME_MS > 0 && window.ZOOCTL_FIRST_FRAME_MS", timeout=120)
        errors = b.errors()
        if errors:
            raise SystemExit(f"the page reported errors: {errors}")
        if marks is not None:
            got = b.evaluate(
                "Object.fromEntries(performance.getEntriesByType('mark').map(m => [m.name, m.startTime]))"
            )
            for k in MARKS:
                if k in got:
                    marks.setdefault(k, []).append(got[k])
        if not play:
            return float(ms), float("nan")
        b.evaluate(
            "window.__shown = 0; new MutationObserver(() => window.__shown++)"
            ".observe(document.getElementById('frame'), {attributes: true, attributeFilter: ['src']}); 1"
        )
        b.evaluate("document.getElementById('play').click()")
        time.sleep(2.0)
        shown = b.evaluate("window.__shown")
        return float(ms), shown / 2.0


def serve(store: Path) -> tuple[subprocess.Popen, str]:
    """`zooctl view bench` serving the fit, as a user starts it; (its process, the URL it prints)."""
    p = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "zooctl",
            "--store",
            str(store),
            "view",
            "bench",
            "--no-browser",
            "--port",
            "0",
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    line = p.stdout.readline()
    if " at http" not in line:
        p.kill()
        raise SystemExit(f"zooctl view did not serve: {line!r}")
    return p, line.split(" at ", 1)[1].split()[0]


def bank_site(store: Path, work: Path, tiles: int) -> Path:
    """A gallery of ``tiles`` tiles: the starter animals' turntables and GLBs, repeated."""
    import dataclasses

    from zooctl_viewer.gallery import load_gallery, write_bank_site

    from zooctl.pipelines.bank_import import seed_starter
    from zooctl.store.bank import Bank

    seed_starter(Bank.open(store), views=False)  # the gallery needs no retrieval views
    entries = load_gallery(store, ["procedural"])
    many = [
        dataclasses.replace(e, name=f"{e.name}-{k}", info=dict(e.info, name=f"{e.name}-{k}"))
        for k in range((tiles + len(entries) - 1) // len(entries))
        for e in entries
    ][:tiles]
    out = work / f"bank-{tiles}"
    write_bank_site(many, out, [])
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--size", type=int, default=240, help="video height and width in pixels")
    ap.add_argument("--repeat", type=int, default=5, help="page loads per case (median)")
    ap.add_argument("--tiles", type=int, default=200, help="gallery tiles (0: no gallery)")
    ap.add_argument("--work", type=Path, default=REPO / "bench" / "out" / "viewer")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args()
    from zooctl_viewer.browser import find_chromium

    if find_chromium() is None:
        raise SystemExit("no chromium (apt-get install chromium)")
    args.work.mkdir(parents=True, exist_ok=True)
    store = make_fit(args.work, args.frames, args.size)
    site = args.work / "site"
    t = time.perf_counter()
    subprocess.run(
        [sys.executable, "-m", "zooctl", "--store", str(store), "view", "bench", "--export", str(site)],
        check=True,
        capture_output=True,
    )
    export_s = time.perf_counter() - t
    results = {"machine": machine(), "frames": args.frames, "size": args.size, "export_s": export_s}
    server, url = serve(store)
    for case, target in (("file", (site / "index.html").as_uri()), ("http", url)):
        marks: dict[str, list[float]] = {}
        runs = [first_frame_ms(target, marks=marks) for _ in range(args.repeat)]
        results[case] = {
            "first_frame_ms": [r[0] for r in runs],
            "median_ms": statistics.median(r[0] for r in runs),
            "play_fps": statistics.median(r[1] for r in runs),
            "marks_median_ms": {k: statistics.median(v) for k, v in marks.items()},
        }
        steps = ", ".join(f"{k.split(':')[1]} {v:.0f}" for k, v in results[case]["marks_median_ms"].items())
        print(f"fit, {case}: first frame {results[case]['median_ms']:.0f} ms (median of {args.repeat}; {steps}), "
              f"plays {results[case]['play_fps']:.1f} frames/s", flush=True)  # fmt: skip
    server.terminate()  # SIGTERM: a background job's children ignore Ctrl-C's SIGINT
    server.wait(60)
    if args.tiles:
        gallery = bank_site(store, args.work, args.tiles)
        runs = [first_frame_ms((gallery / "index.html").as_uri(), play=False)[0] for _ in range(args.repeat)]
        results["bank"] = {"tiles": args.tiles, "first_frame_ms": runs, "median_ms": statistics.median(runs)}
        print(f"bank gallery, {args.tiles} tiles, file: {results['bank']['median_ms']:.0f} ms", flush=True)
    print(json.dumps(results, indent=2))
    if args.out:
        write_json(args.out, results)


if __name__ == "__main__":
    main()
