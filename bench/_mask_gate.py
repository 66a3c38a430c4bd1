"""A per-video gate between two ways of making the masks, chosen leave-one-video-out.

Each video is stored twice by `zooctl video add`: as ``KEPT-name`` (the gate never opens) and as
``OPEN-name`` (it always opens; its report holds the number the gate reads). J per video is the
mean over frames of each frame's J against the truth. For a threshold, a video takes the ``OPEN``
masks when its number exceeds it. The threshold is chosen among a grid as the one with the largest
mean J gain (each set weighing alike) among those under which no set's mean J falls;
leave-one-video-out, each video's threshold is chosen on all the others and it is scored with it.
Sets: ``--davis KEPT OPEN`` (the seven shared DAVIS videos, ``name`` the sequence's) and ``--bench
DIR KEPT OPEN`` (the `zooctl bench make` videos of DIR, ``name`` the folder's, lower case).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
from _util import SHARED

from zooctl.fit.inputs import _read_mask_folder, load_fit_video
from zooctl.paths import default_store
from zooctl.store.videos import VideoStore
from zooctl.video.mask_quality import per_frame_j
from zooctl.video.stats import stored_video_stats

DAVIS = SHARED / "videos"


def main(doc: str, number: Callable[[dict], float | None], grid, number_name: str, opened_name: str) -> None:
    """The command line of a gate's benchmark: ``number(seeding report)`` is what the gate reads."""
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--davis", nargs=2, metavar=("KEPT", "OPEN"))
    ap.add_argument("--bench", nargs=3, action="append", default=[], metavar=("DIR", "KEPT", "OPEN"))
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    report(stored_videos(args, number), grid, number_name, opened_name, args.json)


def measured(
    store: VideoStore, kept: str, opened: str, truth_of, number: Callable[[dict], float | None]
) -> dict:
    """J of the kept and the opened masks, and the number the gate reads (``number(seeding report)``
    of the opened video; NaN when it has none)."""
    rec_kept = store.get(kept, what=("masks",))
    rec_open = store.get(opened, what=("masks",))
    truth = np.asarray(truth_of(rec_kept), bool)
    with h5py.File(store.path(opened), "r") as f:
        x = number(stored_video_stats(f).get("seeding") or {})
    return {
        "before": float(np.mean(per_frame_j(rec_kept.masks, truth))),
        "opened": float(np.mean(per_frame_j(rec_open.masks, truth))),
        "number": float("nan") if x is None else float(x),
    }


def stored_videos(args, number: Callable[[dict], float | None]) -> list[tuple[str, str, dict]]:
    """(set, video, `measured`) of every video the arguments name, from the default store."""
    if not args.davis and not args.bench:
        sys.exit("give --davis KEPT OPEN and/or --bench DIR KEPT OPEN")
    store = VideoStore(default_store())
    videos = []
    if args.davis:
        kept, opened = args.davis
        for name in sorted(p.name for p in DAVIS.iterdir() if (p / "Annotations").is_dir()):

            def truth(rec, name=name):
                return _read_mask_folder(
                    DAVIS / name / "Annotations", rec.source_indices, rec.masks.shape[1:]
                )

            videos.append(
                ("davis", name, measured(store, f"{kept}-{name}", f"{opened}-{name}", truth, number))
            )
    for folder, kept, opened in args.bench:
        for d in sorted(p for p in Path(folder).iterdir() if (p / "video.npz").is_file()):

            def truth(rec, d=d):
                return load_fit_video(d, max_size=100_000).masks

            n = d.name.lower()
            videos.append(
                (Path(folder).name, d.name, measured(store, f"{kept}-{n}", f"{opened}-{n}", truth, number))
            )
    return videos


def video_j(v: dict, threshold: float) -> float:
    return v["opened"] if np.isfinite(v["number"]) and v["number"] > threshold else v["before"]


def choose(videos: list[tuple[str, str, dict]], grid) -> float:
    def gains(t):
        per: dict[str, list[float]] = {}
        for kind, _, v in videos:
            per.setdefault(kind, []).append(video_j(v, t) - v["before"])
        return [float(np.mean(v)) for v in per.values()]

    allowed = [t for t in grid if min(gains(t)) >= 0] or [float(np.inf)]
    return max(allowed, key=lambda t: (np.mean(gains(t)), -t))


def report(videos: list[tuple[str, str, dict]], grid, number_name: str, opened_name: str, json_out) -> None:
    """Choose the threshold on all videos and leave-one-out; print the table; write ``json_out``."""
    chosen = choose(videos, grid)
    table = []
    for i, (kind, name, v) in enumerate(videos):
        loo = choose(videos[:i] + videos[i + 1 :], grid)
        table.append(
            {
                "set": kind,
                "video": name,
                **v,
                "in_sample": video_j(v, chosen),
                "leave_one_out": video_j(v, loo),
                "loo_threshold": loo,
            }
        )
    print(f"threshold chosen on all: {chosen}")
    print(
        f"| set | videos | J before | {opened_name}, in-sample | {opened_name}, leave-one-out "
        f"| higher / lower (LOO) | J every video {opened_name} |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|")
    for kind in dict.fromkeys(r["set"] for r in table):
        rs = [r for r in table if r["set"] == kind]
        up = sum(r["leave_one_out"] > r["before"] + 0.005 for r in rs)
        down = sum(r["leave_one_out"] < r["before"] - 0.005 for r in rs)
        mean = {k: np.mean([r[k] for r in rs]) for k in ("before", "in_sample", "leave_one_out", "opened")}
        print(
            f"| {kind} | {len(rs)} | {mean['before']:.3f} | {mean['in_sample']:.3f} | {mean['leave_one_out']:.3f} "
            f"| {up} / {down} | {mean['opened']:.3f} |"
        )
    for r in table:
        print(
            f"  {r['set']:6s} {r['video']:16s} {number_name} {r['number']:+.3f}  {r['before']:.3f} -> "
            f"{r['in_sample']:.3f} (LOO {r['leave_one_out']:.3f} at {r['loo_threshold']}; "
            f"{opened_name} {r['opened']:.3f})"
        )
    if json_out:
        json_out.write_text(json.dumps({"threshold": chosen, "videos": table}, indent=1))
