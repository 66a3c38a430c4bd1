"""Video preprocessing benchmarks: segmentation quality (J) on DAVIS and throughput (frames/s).

    .venv/bin/python bench/video.py                      # both parts, all three sequences
    .venv/bin/python bench/video.py --part quality       # mean region IoU (J): no box, first-frame box
    .venv/bin/python bench/video.py --part throughput --repeats 3

Quality: each shared DAVIS sequence (``../shared/data/videos/{blackswan,dog,cows}``) is decoded at
the default size (854 px, DAVIS's own 480p) and segmented by `grabcut` twice: (a) with no box (its
localiser finds the animal) and (b) with only the box of the first ground-truth mask. J is the mean over frames of |mask & truth| / |mask | truth| (all
frames, the first included, as DAVIS reports it). Throughput: frames per second of decode (JPEG
folder and H.264 file), DIS flow (forward + backward + occlusion check), segmentation, and writing
the HDF5 store, at 480p and at 256 px; each is the median of ``--repeats`` runs.
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
    from zooctl.video.flow import DISFlow, compute_video_flow

    out: dict = {"no_box": {}, "box": {}}
    for seq in sequences:
        t0 = time.perf_counter()
        dv = decode(VIDEOS / seq, max_size=max_size)
        t1 = time.perf_counter()
        vf = compute_video_flow(DISFlow(preset), dv.frames)
        t2 = time.perf_counter()
        truth = load_truth(seq, dv.frames.shape)
        for mode, box in (("no_box", None), ("box", cues.box_of(truth[0]))):
            seg = get_registry().get("segmenter", "grabcut").create()
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


def _median_fps(fn, n_frames: int, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return n_frames / statistics.median(times)


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
    from zooctl.video.flow import DISFlow, compute_video_flow

    dv = decode(VIDEOS / seq, max_size=size)
    t = len(dv.frames)
    r = {"frames": t, "size": f"{dv.frames.shape[2]}x{dv.frames.shape[1]}"}
    r["decode_jpeg_fps"] = _median_fps(lambda: decode(VIDEOS / seq / "JPEGImages", max_size=size), t, repeats)
    r["decode_mp4_fps"] = _median_fps(lambda: decode(mp4, max_size=size), t, repeats)
    est = DISFlow(preset)
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
    return r


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--part", choices=("all", "quality", "throughput"), default="all")
    ap.add_argument("--sequences", default=",".join(SEQUENCES))
    ap.add_argument(
        "--max-size", type=int, default=854, help="frame size for the quality part (854: DAVIS 480p)"
    )
    ap.add_argument("--preset", default="medium", help="DIS preset")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--throughput-sequence", default="dog")
    ap.add_argument("--seg-frames", type=int, default=10, help="frames timed for segmentation throughput")
    args = ap.parse_args()
    if not VIDEOS.is_dir():
        sys.exit(f"shared DAVIS videos not found at {VIDEOS}")
    report = {"machine": machine(), "command": " ".join(["python", "bench/video.py", *sys.argv[1:]])}
    print(f"machine: {report['machine']}", file=sys.stderr)
    if args.part in ("all", "quality"):
        print("quality (grabcut: no box, then a first-frame box):", file=sys.stderr)
        report["quality"] = q = quality(args.sequences.split(","), args.max_size, args.preset)
        print(
            f"  mean J: no box {q['no_box']['mean_J']:.3f}, first-frame box {q['box']['mean_J']:.3f}",
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
