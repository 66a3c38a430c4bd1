"""The colour snap's gate chosen leave-one-video-out, and the masks' J with and without it.

    ZOOCTL_STORE=S python bench/colour_snap.py [--davis OFF ALWAYS] [--bench DIR OFF ALWAYS]...
        [--json OUT]

Each video is stored twice by `zooctl video add`: as ``OFF-name`` with ``--seg-option snap=false``
(the masks before the snap) and as ``ALWAYS-name`` with ``--seg-option snap_gain=-1`` (every video
snapped; its report holds the separation gain that the gate reads). ``--davis``: the seven shared
DAVIS videos (``name`` the sequence's); ``--bench DIR``: the `zooctl bench make` videos of DIR
(``name`` the folder's, lower case). J per video is the mean over frames of each frame's J against
the truth. For a threshold, a video keeps the snapped masks when its gain exceeds it, as
`zooctl.video.colour_snap.snap_video` decides. The threshold is chosen among a grid as the one with
the largest mean J gain (each set weighing alike) among those under which no set's mean J falls;
leave-one-video-out, each video's threshold is chosen on all the others and it is scored with it.
"""

from __future__ import annotations

import argparse
import json
import sys
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
GRID = np.round(np.arange(-0.05, 0.21, 0.005), 3)


def measured(store: VideoStore, off: str, always: str, truth_of) -> dict:
    """J of the unsnapped and the snapped masks, and the snapped video's separation gain."""
    rec_off = store.get(off, what=("masks",))
    rec_on = store.get(always, what=("masks",))
    truth = np.asarray(truth_of(rec_off), bool)
    with h5py.File(store.path(always), "r") as f:
        snap = ((stored_video_stats(f).get("seeding") or {}).get("colour_snap")) or {}
    gain = snap.get("separation_gain")
    return {
        "before": float(np.mean(per_frame_j(rec_off.masks, truth))),
        "snapped": float(np.mean(per_frame_j(rec_on.masks, truth))),
        "gain": float("nan") if gain is None else float(gain),
    }


def video_j(v: dict, threshold: float) -> float:
    return v["snapped"] if np.isfinite(v["gain"]) and v["gain"] > threshold else v["before"]


def choose(videos: list[tuple[str, str, dict]]) -> float:
    def gains(t):
        per: dict[str, list[float]] = {}
        for kind, _, v in videos:
            per.setdefault(kind, []).append(video_j(v, t) - v["before"])
        return [float(np.mean(v)) for v in per.values()]

    allowed = [t for t in GRID if min(gains(t)) >= 0] or [float(np.inf)]
    return max(allowed, key=lambda t: (np.mean(gains(t)), -t))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--davis", nargs=2, metavar=("OFF", "ALWAYS"))
    ap.add_argument("--bench", nargs=3, action="append", default=[], metavar=("DIR", "OFF", "ALWAYS"))
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    if not args.davis and not args.bench:
        sys.exit("give --davis OFF ALWAYS and/or --bench DIR OFF ALWAYS")
    store = VideoStore(default_store())
    videos = []
    if args.davis:
        off, always = args.davis
        for name in sorted(p.name for p in DAVIS.iterdir() if (p / "Annotations").is_dir()):

            def truth(rec, name=name):
                return _read_mask_folder(
                    DAVIS / name / "Annotations", rec.source_indices, rec.masks.shape[1:]
                )

            videos.append(("davis", name, measured(store, f"{off}-{name}", f"{always}-{name}", truth)))
    for folder, off, always in args.bench:
        for d in sorted(p for p in Path(folder).iterdir() if (p / "video.npz").is_file()):

            def truth(rec, d=d):
                return load_fit_video(d, max_size=100_000).masks

            n = d.name.lower()
            videos.append((Path(folder).name, d.name, measured(store, f"{off}-{n}", f"{always}-{n}", truth)))
    chosen = choose(videos)
    table = []
    for i, (kind, name, v) in enumerate(videos):
        loo = choose(videos[:i] + videos[i + 1 :])
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
        "| set | videos | J before | snapped, in-sample | snapped, leave-one-out | higher / lower (LOO) | J every video snapped |"
    )
    print("|---|---:|---:|---:|---:|---:|---:|")
    for kind in dict.fromkeys(r["set"] for r in table):
        rs = [r for r in table if r["set"] == kind]
        up = sum(r["leave_one_out"] > r["before"] + 0.005 for r in rs)
        down = sum(r["leave_one_out"] < r["before"] - 0.005 for r in rs)
        mean = {k: np.mean([r[k] for r in rs]) for k in ("before", "in_sample", "leave_one_out", "snapped")}
        print(
            f"| {kind} | {len(rs)} | {mean['before']:.3f} | {mean['in_sample']:.3f} | {mean['leave_one_out']:.3f} "
            f"| {up} / {down} | {mean['snapped']:.3f} |"
        )
    for r in table:
        print(
            f"  {r['set']:6s} {r['video']:16s} gain {r['gain']:+.3f}  {r['before']:.3f} -> {r['in_sample']:.3f} "
            f"(LOO {r['leave_one_out']:.3f} at {r['loo_threshold']}; snapped {r['snapped']:.3f})"
        )
    if args.json:
        args.json.write_text(json.dumps({"threshold": chosen, "videos": table}, indent=1))


if __name__ == "__main__":
    main()
