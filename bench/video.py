"""Video preprocessing benchmarks: segmentation quality (J) on DAVIS and throughput (frames/s).

    .venv/bin/python bench/video.py                      # both parts, all three sequences
    .venv/bin/python bench/video.py --part quality       # mean region IoU (J): no box, first-frame box
    .venv/bin/python bench/video.py --part throughput --repeats 3
    .venv/bin/python bench/video.py --part quality --seg-option key_every=5 --flow-size 480  # variants

Quality: each shared DAVIS sequence (``../shared/data/videos/{blackswan,dog,cows}``) is decoded at
the default size (854 px, DAVIS's own 480p) and segmented by `grabcut` twice: (a) with no box (its
localiser finds the animal) and (b) with only the box of the first ground-truth mask. J is the mean over frames of |mask & truth| / |mask | truth| (all
frames, the first included, as DAVIS reports it). Throughput: frames per second of decode (JPEG
folder and H.264 file), DIS flow (forward + backward + occlusion check), segmentation, and writing
the HDF5 store, at 480p and at 256 px, and of a whole `video add` of the JPEG folder (decode, flow,
no-box masks, store: stages overlap there), with its CPU seconds; each is the median of ``--repeats`` runs.
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
VIDEOS = REPO.parent / "shared" / "data" / "videos"
SEQUENCES = ("blackswan", "dog", "cows")


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


def quality(sequences, max_size: int, preset: str) -> dict:
    """J per sequence with (a) no box (the localiser seeds) and (b) the first true mask's box;
    ``add_fps``: frames per second of decode + flow + no-box masks, what `video add` does."""
    from zooctl.plugins import get_registry
    from zooctl.video import cues
    from zooctl.video.decode import decode
    from zooctl.video.flow import compute_video_flow

    out: dict = {"no_box": {}, "box": {}}
    for seq in sequences:
        t0 = time.perf_counter()
        dv = decode(VIDEOS / seq, max_size=max_size)
        t1 = time.perf_counter()
        vf = compute_video_flow(_dis(preset), dv.frames)
        t2 = time.perf_counter()
        truth = load_truth(seq, dv.frames.shape)
        for mode, box in (("no_box", None), ("box", cues.box_of(truth[0]))):
            seg = get_registry().get("segmenter", "grabcut").create(**SEG_OPTIONS)
            t3 = time.perf_counter()
            masks = seg.segment(dv.frames, box=box, flow=vf)
            t4 = time.perf_counter()
            j = [float((m & g).sum() / max((m | g).sum(), 1)) for m, g in zip(masks, truth)]
            how = seg.report.get("seeding", [])
            r = {
                "frames": len(j),
                "J": float(np.mean(j)),
                "J_min": float(np.min(j)),
                "segment_s": t4 - t3,
                "seed_frame": seg.report.get("seed_frame"),
                "re_seeded": how.count("re-seeded"),
                "empty": how.count("empty"),
                "classes": [c["name"] for c in seg.report.get("animal_classes", [])],
            }
            if mode == "no_box":
                r["add_fps"] = len(j) / (t1 - t0 + t2 - t1 + t4 - t3)
                r["decode_s"], r["flow_s"] = t1 - t0, t2 - t1
            out[mode][seq] = r
            if _OVERLAYS is not None:
                _overlay(_OVERLAYS / f"{seq}_{mode}.png", dv.frames, masks, truth)
            print(
                f"  {seq:10s} {mode:6s} J={r['J']:.3f} (min {r['J_min']:.3f}) {len(j)} frames, "
                f"segment {t4 - t3:.1f}s, seed frame {r['seed_frame']}, {r['re_seeded']} re-seeded, "
                f"{r['empty']} empty, saw {', '.join(r['classes'])}"
                + (f"; decode+flow+masks {r['add_fps']:.1f} frames/s" if mode == "no_box" else ""),
                file=sys.stderr,
                flush=True,
            )
    for mode in ("no_box", "box"):
        out[mode]["mean_J"] = float(np.mean([out[mode][s]["J"] for s in sequences]))
    return out


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
        seq = SEQUENCES[k % len(SEQUENCES)]
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


def composited_quality(assets, frames: int, size: int, preset: str) -> dict:
    """J per composited video, no box and first-frame box (see `composited_set`)."""
    from zooctl.plugins import get_registry
    from zooctl.video import cues
    from zooctl.video.flow import compute_video_flow

    out: dict = {"no_box": {}, "box": {}}
    with tempfile.TemporaryDirectory() as tmp:
        videos = composited_set(assets, frames, size, Path(tmp))
    for name, (rgb, truth) in videos.items():
        vf = compute_video_flow(_dis(preset), rgb)
        for mode, box in (("no_box", None), ("box", cues.box_of(truth[0]))):
            seg = get_registry().get("segmenter", "grabcut").create(**SEG_OPTIONS)
            masks = seg.segment(rgb, box=box, flow=vf)
            j = [float((m & g).sum() / max((m | g).sum(), 1)) for m, g in zip(masks, truth)]
            out[mode][name] = {"frames": len(j), "J": float(np.mean(j)), "J_min": float(np.min(j))}
            print(
                f"  {name:16s} {mode:6s} J={np.mean(j):.3f} (min {np.min(j):.3f}), "
                f"saw {', '.join(c['name'] for c in seg.report.get('animal_classes', []))}",
                file=sys.stderr,
                flush=True,
            )
            if _OVERLAYS is not None:
                _overlay(_OVERLAYS / f"{name.replace('/', '_')}_{mode}.png", rgb, masks, truth)
    for mode in ("no_box", "box"):
        out[mode]["mean_J"] = float(np.mean([v["J"] for k, v in out[mode].items()]))
    return out


_OVERLAYS: Path | None = None
FLOW_SIZE: int | None = None  # --flow-size: longest side DIS works at (None: its default)
SEG_OPTIONS: dict = {}  # --seg-option: the grabcut options measured (defaults when empty)


def _overlay(path: Path, frames, masks, truth) -> None:
    """Six frames: the mask tinted green, the truth outlined red."""
    import cv2

    tiles = []
    for i in np.linspace(0, len(frames) - 1, 6).astype(int):
        f = frames[i].copy()
        f[masks[i]] = (0.5 * f[masks[i]] + [0, 120, 0]).astype(np.uint8)
        c, _ = cv2.findContours(truth[i].astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(f, c, -1, (255, 0, 0), 1)
        tiles.append(f)
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), np.vstack([np.hstack(tiles[:3]), np.hstack(tiles[3:])])[..., ::-1])


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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--part", choices=("all", "quality", "throughput"), default="all")
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
    ap.add_argument("--overlays", type=Path, default=None, help="write mask overlay PNGs here")
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
    global _OVERLAYS, FLOW_SIZE
    FLOW_SIZE = args.flow_size
    for kv in args.seg_option:
        k, _, v = kv.partition("=")
        try:
            SEG_OPTIONS[k] = json.loads(v)  # numbers, true/false
        except json.JSONDecodeError:
            SEG_OPTIONS[k] = v
    _OVERLAYS = args.overlays
    if not VIDEOS.is_dir():
        sys.exit(f"shared DAVIS videos not found at {VIDEOS}")
    report = {"machine": machine(), "command": " ".join(["python", "bench/video.py", *sys.argv[1:]])}
    print(f"machine: {report['machine']}", file=sys.stderr)
    if args.part in ("all", "quality"):
        if args.sequences:
            print("quality (grabcut: no box, then a first-frame box):", file=sys.stderr)
            report["quality"] = q = quality(args.sequences.split(","), args.max_size, args.preset)
            print(
                f"  mean J: no box {q['no_box']['mean_J']:.3f}, first-frame box {q['box']['mean_J']:.3f}",
                file=sys.stderr,
            )
        if args.composited:
            print("quality on rendered animals over painted-out DAVIS backgrounds:", file=sys.stderr)
            report["composited"] = c = composited_quality(
                args.composited.split(","), args.composited_frames, 320, args.preset
            )
            print(
                f"  mean J: no box {c['no_box']['mean_J']:.3f}, first-frame box {c['box']['mean_J']:.3f}",
                file=sys.stderr,
            )
    if args.part in ("all", "throughput"):
        print(f"throughput ({args.throughput_sequence}, median of {args.repeats}):", file=sys.stderr)
        report["throughput"] = throughput(
            args.throughput_sequence, (854, 256), args.repeats, args.preset, args.seg_frames
        )
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
