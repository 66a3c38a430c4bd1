"""Video preprocessing benchmarks: segmentation quality (J) on DAVIS and throughput (frames/s).

    .venv/bin/python bench/video.py                      # quality and throughput
    .venv/bin/python bench/video.py --part quality       # J per video, grid chosen leave-one-out
    .venv/bin/python bench/video.py --part quality --segmenter selftrain  # and the learned segmenter
    .venv/bin/python bench/video.py --part quality --segmenter animalnet  # the default; --weights W.npz: other weights
    .venv/bin/python bench/video.py --part hard          # panning off the animal, every third frame
    .venv/bin/python bench/video.py --part throughput --repeats 3
    .venv/bin/python bench/video.py --part quality --seg-option key_every=5 --flow-size 480  # variants
    .venv/bin/python bench/video.py --part length --lengths 5,20,60 --repeats 1   # `video add` by length
    .venv/bin/python bench/video.py --part length --lengths 5,60 --fit   # and `zooctl fit CLIP` of each

Quality: the seven shared real videos (``../shared/data/videos``; blackswan, dog and cows are the
ones the segmenter was developed on) are decoded at the default size (854 px, DAVIS's own 480p) and
segmented by `grabcut` with no box, as `video add` does (its localiser finds the animal), at its
defaults and at each value of a small grid of settings that were chosen by looking at videos
(``--grid``; each varied alone), and each setting is also chosen leave-one-video-out: picked on six
videos, scored on the seventh (`bench/video_quality.py`, `zooctl.video.mask_quality`). J is the
mean over frames of |mask & truth| / |mask | truth| (all frames, the first included, as DAVIS
reports it; a frame where both are empty counts 1). ``--box``: also with only the box of the
first ground-truth mask. Then the composited set (rendered animals over painted-out DAVIS
backgrounds). Written to ``--out``: the table (quality.md), quality.json, a J-per-frame plot and an
overlay sheet per video; flow and masks are cached (``--cache``) by frames, settings and source.
Throughput: frames per second of decode (JPEG
folder and H.264 file), DIS flow (forward + backward + occlusion check), segmentation, and writing
the HDF5 store, at 480p and at 256 px, and of a whole `video add` of the JPEG folder (decode, flow,
no-box masks, store: stages overlap there), with its CPU seconds; each is the median of ``--repeats`` runs.
Length: `zooctl video add` with the defaults of 1080p 30 fps clips of 5, 20 and 60 s made from the
DAVIS dog (upscaled and looped with OpenCV, in the temp folder), each in a child process: wall and
CPU seconds, peak memory (the child's ru_maxrss) and the frames its frame budget kept.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from video_quality import GRID, Cache  # noqa: E402  (bench/ is on the path when run as a script)

VIDEOS = REPO.parent / "shared" / "data" / "videos"
SEQUENCES = ("blackswan", "dog", "cows", "bear", "elephant", "dog-agility", "mallard-water")
BACKGROUNDS = ("blackswan", "dog", "cows")  # the composited set's background videos


def _dis(preset: str):
    from zooctl.video.flow import DISFlow

    return DISFlow(preset) if FLOW_SIZE is None else DISFlow(preset, max_size=FLOW_SIZE)


def machine() -> str:
    import cv2
    from _util import machine as base_machine

    return f"{base_machine()}, OpenCV {cv2.__version__} with {cv2.getNumThreads()} threads"


def load_truth(seq: str, frames_shape) -> np.ndarray:
    from zooctl.video.decode import decode
    from zooctl.video.segment import MaskSegmenter

    dv = decode(VIDEOS / seq, max_size=None)
    h, w = frames_shape[1:3]
    return MaskSegmenter(VIDEOS / seq, dv.source_indices, dv.original_size).segment(
        np.zeros((len(dv.frames), h, w, 3), np.uint8)
    )


def loader(max_size: int):
    """``load(seq)`` -> (frames, truth) of a shared DAVIS video decoded at ``max_size``."""
    from zooctl.video.decode import decode

    def load(seq):
        dv = decode(VIDEOS / seq, max_size=max_size)
        return dv.frames, load_truth(seq, dv.frames.shape)

    return load


def quality(sequences, max_size: int, preset: str, out: Path, cache, grid: dict, box: bool) -> dict:
    """J per video with no box (the localiser seeds, as `video add` does) at the segmenter's
    defaults and at each grid setting, chosen leave-one-video-out (`video_quality`); with ``box``
    also at the defaults given the first true mask's box."""
    from video_quality import leave_one_out_table, run_real, segment_video

    from zooctl.video import cues

    load = loader(max_size)
    report = run_real(sequences, load, cache, SEG_OPTIONS, grid, preset, FLOW_SIZE, out)
    if len(sequences) >= 2:
        table, report["leave_one_out"] = leave_one_out_table(report)
        (out / "quality.md").write_text(table)
        print(table, file=sys.stderr)
    if box:
        report["box"] = {}
        for seq in sequences:
            frames, truth = load(seq)
            _, r = segment_video(
                seq, frames, truth, cache, SEG_OPTIONS, {}, preset, FLOW_SIZE, box=cues.box_of(truth[0])
            )
            report["box"][seq] = r
            print(f"  {seq:14s} first-frame box J={r['J']:.3f} (min {r['J_min']:.3f})", file=sys.stderr)
    return report


def learned_quality(module: str, sequences, max_size: int, preset: str, out: Path, cache, **kw) -> dict:
    """A learned segmenter against `grabcut` on the shared videos, its settings chosen
    leave-one-video-out: ``module`` `video_selftrain` (`selftrain`) or `video_animalnet`
    (`animalnet`, ``weights=`` from `zooctl segment train`); the table goes to NAME.md."""
    import importlib

    bench = importlib.import_module(module)
    name = module.removeprefix("video_")

    report = bench.run(sequences, loader(max_size), cache, SEG_OPTIONS, preset, FLOW_SIZE, out, **kw)
    if len(sequences) >= 2:
        text, report["leave_one_out"] = bench.table(report)
        (out / f"{name}.md").write_text(text)
        (out / f"{name}.json").write_text(json.dumps(report, indent=1))
        print(text, file=sys.stderr)
    return report


def composited_set(assets, frames: int, size: int, tmp: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Rendered animals (`zooctl bench make`) over real backgrounds: each DAVIS sequence with its
    animal painted out (OpenCV inpainting over the dilated true mask) and a square crop taken,
    so the background is real texture that moves as the DAVIS camera did. {name: (frames, masks)}."""
    import subprocess

    import cv2

    from zooctl.video.decode import decode

    bank = REPO.parent / "shared" / "data" / "assets" / "quaternius" / "animals_pack"
    cmd = [
        sys.executable,
        "-m",
        "zooctl",
        "--store",
        str(tmp / "store"),
        "bench",
        "make",
        "--out",
        str(tmp / "made"),
    ]
    cmd += ["--bank", str(bank), "--frames", str(frames), "--size", str(size)]
    for a in assets:
        cmd += ["--asset", a]
    subprocess.run(
        cmd, check=True, capture_output=True, env={**__import__("os").environ, "PYTHONPATH": str(REPO)}
    )
    out = {}
    for k, a in enumerate(assets):
        seq = BACKGROUNDS[k % len(BACKGROUNDS)]
        dv = decode(VIDEOS / seq, max_size=427, max_frames=frames)
        truth = load_truth(seq, dv.frames.shape)
        with np.load(tmp / "made" / a / "video.npz") as z:
            fg, masks = z["frames"], z["masks"]
        h, w = dv.frames.shape[1:3]
        x0 = (w - h) // 2 + (k % 3 - 1) * (w - h) // 2  # left, middle or right square
        comp = np.empty_like(fg)
        for i in range(len(fg)):
            j = i % len(dv.frames)
            hole = cv2.dilate(truth[j].astype(np.uint8), np.ones((15, 15), np.uint8))
            bg = cv2.inpaint(dv.frames[j], hole, 5, cv2.INPAINT_TELEA)[:, x0 : x0 + h]
            bg = cv2.resize(bg, (size, size), interpolation=cv2.INTER_LINEAR)
            comp[i] = np.where(masks[i][..., None], fg[i], bg)
        out[f"{a}/{seq}"] = (comp, masks)
    return out


def composited_quality(assets, frames: int, size: int, preset: str, out: Path, cache, box: bool) -> dict:
    """J per composited video (see `composited_set`) at the defaults, no box (and with ``box``
    the first true mask's box); curves and overlays beside the real videos'."""
    from video_quality import curve_plot, overlay_sheet, segment_video

    from zooctl.video import cues

    res: dict = {"no_box": {}, "box": {}}
    with tempfile.TemporaryDirectory() as tmp:
        videos = composited_set(assets, frames, size, Path(tmp))
    for name, (rgb, truth) in videos.items():
        for mode in ("no_box", "box") if box else ("no_box",):
            hint = cues.box_of(truth[0]) if mode == "box" else None
            masks, r = segment_video(name, rgb, truth, cache, SEG_OPTIONS, {}, preset, FLOW_SIZE, box=hint)
            res[mode][name] = r
            print(
                f"  {name:16s} {mode:6s} J={r['J']:.3f} (min {r['J_min']:.3f}), saw {', '.join(r['classes'])}",
                file=sys.stderr,
                flush=True,
            )
            if mode == "no_box":
                stem = "composited_" + name.replace("/", "_")
                overlay_sheet(out / "overlays" / f"{stem}.png", rgb, masks, truth, r["per_frame"], width=320)
                curve_plot(out / "curves" / f"{stem}.png", name, {"default": r["per_frame"]}, r)
    for mode in ("no_box", "box"):
        if res[mode]:
            res[mode]["mean_J"] = float(np.mean([v["J"] for v in res[mode].values()]))
    return res


FLOW_SIZE: int | None = None  # --flow-size: longest side DIS works at (None: its default)
SEG_OPTIONS: dict = {}  # --seg-option: the grabcut options measured (defaults when empty)


def _median_fps(fn, n_frames: int, repeats: int) -> float:
    return n_frames / _median_times(fn, repeats)[0]


def _median_times(fn, repeats: int) -> tuple[float, float]:
    """Median wall and CPU (user + system, all threads) seconds of ``fn()``."""
    import resource

    def cpu() -> float:
        r = resource.getrusage(resource.RUSAGE_SELF)
        return r.ru_utime + r.ru_stime

    walls, cpus = [], []
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), cpu()
        fn()
        walls.append(time.perf_counter() - t0)
        cpus.append(cpu() - c0)
    return statistics.median(walls), statistics.median(cpus)


def throughput(seq: str, sizes, repeats: int, preset: str, seg_frames: int) -> dict:
    from zooctl.io.video import write_mp4
    from zooctl.video.decode import decode

    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        full = decode(VIDEOS / seq, max_size=None)
        mp4 = write_mp4(Path(tmp) / f"{seq}.mp4", full.frames, fps=24, quality=18)
        for size in sizes:
            r = throughput_at(seq, mp4, size, Path(tmp) / f"store{size}", repeats, preset, seg_frames)
            results[f"{size}px"] = r
            print(
                f"  {size}px: "
                + ", ".join(f"{k}={v:.1f}" if isinstance(v, float) else f"{k}={v}" for k, v in r.items()),
                file=sys.stderr,
                flush=True,
            )
    return results


def throughput_at(
    seq: str, mp4: Path, size: int, store_root: Path, repeats: int, preset: str, seg_frames: int
) -> dict:
    """Frames/s of each stage at one frame size (longest side ``size``)."""
    from zooctl.plugins import get_registry
    from zooctl.store.videos import VideoRecord, VideoStore
    from zooctl.video import cues
    from zooctl.video.decode import decode
    from zooctl.video.flow import compute_video_flow
    from zooctl.video.ingest import AddOptions, add_video

    dv = decode(VIDEOS / seq, max_size=size)
    t = len(dv.frames)
    r = {"frames": t, "size": f"{dv.frames.shape[2]}x{dv.frames.shape[1]}"}
    r["decode_jpeg_fps"] = _median_fps(lambda: decode(VIDEOS / seq / "JPEGImages", max_size=size), t, repeats)
    r["decode_mp4_fps"] = _median_fps(lambda: decode(mp4, max_size=size), t, repeats)
    est = _dis(preset)
    holder = {}

    def flow():
        holder["vf"] = compute_video_flow(est, dv.frames)

    r["flow_fps"] = _median_fps(flow, t - 1, repeats)
    vf = holder["vf"]
    truth = load_truth(seq, dv.frames.shape)
    n = min(seg_frames, t)
    sub = compute_video_flow(est, dv.frames[:n])
    seg = get_registry().get("segmenter", "grabcut").create()
    r["segment_fps"] = _median_fps(
        lambda: seg.segment(dv.frames[:n], box=cues.box_of(truth[0]), flow=sub), n, 1
    )
    rec = VideoRecord(
        "bench",
        dv.frames,
        truth,
        vf.forward,
        vf.backward,
        vf.occlusion_forward,
        vf.occlusion_backward,
        dv.fps,
        {"path": "", "kind": "images", "sha256": "0" * 64},
        dv.source_indices,
        {"name": "masks"},
        {"name": "dis"},
    )
    store = VideoStore(store_root)
    r["store_write_fps"] = _median_fps(lambda: store.add(rec, replace=True), t, repeats)
    r["flow_plus_store_fps"] = 1.0 / (1.0 / r["flow_fps"] + 1.0 / r["store_write_fps"])
    r["h5_bytes_per_frame"] = int(store.path("bench").stat().st_size / t)
    # what `zooctl video add FOLDER` does: decode, flow, no-box masks (the localiser), store write
    opts = AddOptions(name="add", max_size=size, replace=True)
    wall, cpu = _median_times(lambda: add_video(store, VIDEOS / seq / "JPEGImages", opts), repeats)
    r["add_fps"], r["add_cpu_s"] = t / wall, cpu
    return r


def make_clip(path: Path, seconds: float, seq: str = "dog", fps: float = 30.0, size=(1920, 1080)) -> Path:
    """A ``seconds``-long 1080p clip at ``fps``: the shared DAVIS frames of ``seq`` upscaled with
    OpenCV and looped back and forth (no jump at the loop), written with OpenCV's MPEG-4 encoder."""
    import cv2

    from zooctl.video.decode import image_files

    if path.exists():
        return path
    files = image_files(VIDEOS / seq / "JPEGImages")
    frames = [cv2.resize(cv2.imread(str(f)), size, interpolation=cv2.INTER_CUBIC) for f in files]
    order = list(range(len(frames))) + list(range(len(frames) - 2, 0, -1))
    tmp = path.with_suffix(".part.mp4")
    out = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*"mp4v"), fps, size)
    for i in range(int(round(seconds * fps))):
        out.write(frames[order[i % len(order)]])
    out.release()
    tmp.replace(path)
    return path


def run_child(args: list[str], env: dict | None = None, cwd: Path | None = None) -> dict:
    """Run ``args`` in a child process: its wall seconds, CPU seconds and peak RSS (ru_maxrss)."""
    import os
    import subprocess

    t0 = time.perf_counter()
    p = subprocess.Popen(
        args, cwd=cwd, env={**os.environ, **(env or {})}, stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    _, status, ru = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t0
    out, err = p.stdout.read().decode(), p.stderr.read().decode()
    p.returncode = os.waitstatus_to_exitcode(status)
    if p.returncode:
        raise RuntimeError(f"{' '.join(args)} failed ({p.returncode}): {err[-2000:]}")
    return {
        "wall_s": wall,
        "cpu_s": ru.ru_utime + ru.ru_stime,
        "peak_mb": ru.ru_maxrss / 1024,
        "out": out,
        "err": err,
    }


def length_sweep(
    lengths, repeats: int, extra: list[str], source_tree: Path | None, fit: bool = False
) -> dict:
    """`zooctl video add CLIP` of 1080p 30 fps clips of each length (seconds), with the defaults
    (plus ``extra`` options): wall time, CPU time, peak memory of the process, frames kept; the
    median of ``repeats`` runs each. ``source_tree``: run another checkout's zooctl (a baseline).
    ``fit``: then, once per length, `zooctl fit CLIP` with no options into a fresh store holding
    the starter bank (video add, retrieval, trials and fit in one process), timed the same way."""
    import os
    import shutil

    tmp = Path(tempfile.gettempdir()) / "zooctl-bench-video-length"
    tmp.mkdir(exist_ok=True)
    env = {"PYTHONPATH": str(source_tree or REPO), "OMP_NUM_THREADS": os.environ.get("OMP_NUM_THREADS", "2")}
    out = {}
    for seconds in lengths:
        clip = make_clip(tmp / f"dog_{seconds:g}s_1080p30.mp4", seconds)
        runs = []
        for _ in range(repeats):
            store = tmp / f"store-{seconds:g}s"
            shutil.rmtree(store, ignore_errors=True)
            cmd = [
                sys.executable,
                "-m",
                "zooctl",
                "--store",
                str(store),
                "video",
                "add",
                str(clip),
                "--json",
                *extra,
            ]
            try:
                r = run_child(cmd, env, cwd=source_tree or REPO)  # `-m` imports from the cwd first
            except RuntimeError as exc:
                runs.append({"error": str(exc).splitlines()[-1][:300]})
                break
            summary = json.loads(r.pop("out"))
            r.pop("err")
            runs.append({**r, "frames": summary["frames"], "fps": summary["fps"]})
        ok = [r for r in runs if "error" not in r]
        if not ok:
            out[f"{seconds:g}s"] = runs[0]
            print(f"  {seconds:g} s: {runs[0]['error']}", file=sys.stderr, flush=True)
            continue
        med = {k: statistics.median(r[k] for r in ok) for k in ("wall_s", "cpu_s", "peak_mb")}
        med.update(frames=ok[0]["frames"], fps=ok[0]["fps"], runs=len(ok))
        med["wall_s_per_frame"] = med["wall_s"] / med["frames"]
        out[f"{seconds:g}s"] = med
        print(
            f"  {seconds:g} s clip: kept {med['frames']} frames at {med['fps']:g} fps, wall {med['wall_s']:.1f} s "
            f"({med['wall_s_per_frame']:.2f} s/frame), CPU {med['cpu_s']:.1f} s, peak {med['peak_mb']:.0f} MB",
            file=sys.stderr,
            flush=True,
        )
        if fit:
            med["fit"] = fit_clip(clip, tmp / f"fitstore-{seconds:g}s", env, source_tree)
    return out


def fit_clip(clip: Path, store: Path, env: dict, source_tree: Path | None) -> dict:
    """`zooctl fit CLIP` with no options into a fresh ``store`` seeded with the starter bank."""
    import shutil

    shutil.rmtree(store, ignore_errors=True)
    base = [sys.executable, "-m", "zooctl", "--store", str(store)]
    run_child([*base, "bank", "seed"], env, cwd=source_tree or REPO)
    r = run_child([*base, "fit", str(clip), "--json"], env, cwd=source_tree or REPO)
    rec = json.loads(r.pop("out"))
    r.pop("err")
    res = {
        **r,
        "frames": rec["frames"],
        "template": rec["template"],
        "stage_iters": {k: v.get("steps") for k, v in rec.get("losses", {}).items()},
        "timings": rec["timings"],
        "mask_iou": rec["metrics"]["mask_iou"],
        "overlay_frames_expected": rec["frames"] + 60,
    }
    print(
        f"    fit: {res['frames']} frames, template {res['template']}, wall {r['wall_s']:.0f} s, "
        f"CPU {r['cpu_s']:.0f} s, peak {r['peak_mb']:.0f} MB, mask IoU {res['mask_iou']:.3f} (against its own automatic masks)",
        file=sys.stderr,
        flush=True,
    )
    return res


def _value(text: str):
    try:
        return json.loads(text)  # numbers, true/false
    except json.JSONDecodeError:
        return text


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--part", choices=("all", "quality", "hard", "throughput", "length"), default="all")
    ap.add_argument("--lengths", default="5,20,60", help="clip lengths in seconds for --part length")
    ap.add_argument("--fit", action="store_true", help="length part: also `zooctl fit CLIP` once per length")
    ap.add_argument(
        "--add-option",
        action="append",
        default=[],
        metavar="OPT",
        help="extra `video add` option (length part)",
    )
    ap.add_argument(
        "--baseline", type=Path, default=None, help="another checkout's tree to time (length part)"
    )
    ap.add_argument("--sequences", default=",".join(SEQUENCES), help="DAVIS sequences ('' to skip)")
    ap.add_argument(
        "--max-size", type=int, default=854, help="frame size for the quality part (854: DAVIS 480p)"
    )
    ap.add_argument("--preset", default="medium", help="DIS preset")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--throughput-sequence", default="dog")
    ap.add_argument("--seg-frames", type=int, default=10, help="frames timed for segmentation throughput")
    ap.add_argument(
        "--composited",
        default="Horse,Fox,Cow,Deer,Wolf,Alpaca",
        help="animals_pack assets rendered over DAVIS backgrounds ('' to skip)",
    )
    ap.add_argument("--composited-frames", type=int, default=30)
    ap.add_argument(
        "--out",
        type=Path,
        default=REPO / "bench" / "out" / "video_quality",
        help="quality part: table, JSON, J curves and overlay sheets go here",
    )
    ap.add_argument(
        "--cache",
        default=str(REPO / "bench" / "out" / "video_cache"),
        help="flow and masks cached here, keyed by frames, settings and source ('' for none)",
    )
    ap.add_argument(
        "--grid",
        action="append",
        default=None,
        metavar="K=V1,V2,..",
        help="grabcut setting and the values chosen among leave-one-video-out (repeatable; "
        "default: "
        + "; ".join(f"{k}={','.join(map(str, v))}" for k, v in GRID.items())
        + "; 'none': no grid)",
    )
    ap.add_argument("--box", action="store_true", help="quality part: also the first true mask's box")
    ap.add_argument(
        "--segmenter",
        choices=("grabcut", "selftrain", "animalnet"),
        default="grabcut",
        help="quality part: selftrain (bench/video_selftrain.py) or animalnet (bench/video_animalnet.py, "
        "needs --weights) also runs that learned segmenter and its grid",
    )
    ap.add_argument(
        "--weights",
        type=Path,
        default=None,
        help="animalnet weights .npz (zooctl segment train; default: the shipped ones)",
    )
    ap.add_argument(
        "--seg-option", action="append", default=[], metavar="K=V", help="grabcut option to measure"
    )
    ap.add_argument(
        "--flow-size",
        type=int,
        default=None,
        help="longest side DIS flow works at (0: full size; default: DISFlow's)",
    )
    args = ap.parse_args()
    global FLOW_SIZE
    FLOW_SIZE = args.flow_size
    for kv in args.seg_option:
        k, _, v = kv.partition("=")
        SEG_OPTIONS[k] = _value(v)
    grid = dict(GRID)
    if args.grid is not None:
        grid = {}
        for kv in args.grid:
            if kv != "none":
                k, _, vs = kv.partition("=")
                grid[k] = tuple(_value(v) for v in vs.split(","))
    cache = Cache(Path(args.cache) if args.cache else None)
    if not VIDEOS.is_dir():
        sys.exit(f"shared DAVIS videos not found at {VIDEOS}")
    report = {"machine": machine(), "command": " ".join(["python", "bench/video.py", *sys.argv[1:]])}
    print(f"machine: {report['machine']}", file=sys.stderr)
    if args.part in ("all", "quality"):
        args.out.mkdir(parents=True, exist_ok=True)
        if args.sequences:
            print("quality (grabcut, no box; each grid setting varied alone):", file=sys.stderr)
            report["quality"] = quality(
                args.sequences.split(","), args.max_size, args.preset, args.out, cache, grid, args.box
            )
        if args.sequences and args.segmenter == "selftrain":
            print("quality of selftrain (no box; each of its grid settings varied alone):", file=sys.stderr)
            report["selftrain"] = learned_quality(
                "video_selftrain", args.sequences.split(","), args.max_size, args.preset, args.out, cache
            )
        if args.sequences and args.segmenter == "animalnet":
            print("quality of animalnet (no box; its weights chosen leave-one-out):", file=sys.stderr)
            report["animalnet"] = learned_quality(
                "video_animalnet",
                args.sequences.split(","),
                args.max_size,
                args.preset,
                args.out,
                cache,
                weights=args.weights,
            )
        if args.composited:
            print("quality on rendered animals over painted-out DAVIS backgrounds:", file=sys.stderr)
            report["composited"] = c = composited_quality(
                args.composited.split(","),
                args.composited_frames,
                320,
                args.preset,
                args.out,
                cache,
                args.box,
            )
            print(f"  mean J, no box: {c['no_box']['mean_J']:.3f}", file=sys.stderr)
        (args.out / "quality.json").write_text(json.dumps(report, indent=1))
    if args.part == "hard" and args.sequences:
        import video_hard

        args.out.mkdir(parents=True, exist_ok=True)
        print("hard cases made from the shared videos (grabcut and the default animalnet):", file=sys.stderr)
        report["hard"] = video_hard.run(
            args.sequences.split(","),
            loader(args.max_size),
            cache,
            SEG_OPTIONS,
            args.preset,
            FLOW_SIZE,
            args.out,
            args.weights,
        )
        text = video_hard.table(report["hard"])
        (args.out / "hard.md").write_text(text)
        (args.out / "hard.json").write_text(json.dumps(report["hard"], indent=1))
        print(text, file=sys.stderr)
    if args.part in ("all", "throughput"):
        print(f"throughput ({args.throughput_sequence}, median of {args.repeats}):", file=sys.stderr)
        report["throughput"] = throughput(
            args.throughput_sequence, (854, 256), args.repeats, args.preset, args.seg_frames
        )
    if args.part == "length":
        lengths = [float(x) for x in args.lengths.split(",")]
        print(f"video add of 1080p 30 fps clips (median of {args.repeats}):", file=sys.stderr)
        report["length"] = length_sweep(lengths, args.repeats, args.add_option, args.baseline, args.fit)
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
