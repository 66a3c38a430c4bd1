"""Videos with and without an animal through `zooctl video add`, and the animal check's rule
chosen leave-one-video-out (`zooctl.video.animal_check`; BENCHMARKS.md, "A video with no animal").

    python bench/animal_check.py make OUT [--scenes BENCH_DIR] [--count 10]
    ZOOCTL_STORE=S python bench/animal_check.py collect OUT --videos BENCH_DIR... [--davis]
    python bench/animal_check.py choose OUT

``make`` writes clips with no animal in them into OUT/clips: each shared DAVIS video cropped to
the largest window (at least 160 px a side, aspect 0.66-1.8) its animal never enters over the
clip, dilated by 20 px (``neg-VIDEO``); and ``--count`` natural scenes of `zooctl bench make`'s
world background, each seen along the camera track of every third video of ``--scenes`` (a
`bench make --background world` folder) with a scene seed of its own (``syn-sceneK``).

``collect`` stores every clip of OUT/clips, the DAVIS videos as given (``--davis``: ``jpeg-VIDEO``)
and every video of each ``--videos`` folder (``FOLDER-NAME``) with `video add`'s defaults, and writes each stored video's check
(``animal_check`` of its segmenter report) to OUT/checks.jsonl.

``choose`` fits the rule's three thresholds (regions, looks, empty share) on a grid, as the
smallest false-warning rate plus miss rate, ties to the middle of the best looks, and again with
each video left out (a DAVIS video together with its crop); prints the in-sample and
leave-one-out errors.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

import cv2
import numpy as np
from _util import SHARED

DAVIS = SHARED / "videos"
LOOKS = np.round(np.arange(0.0, 1.0001, 0.05), 2)
EMPTY = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 1.01)
REGIONS = (1, 2, 3)


def free_window(used: np.ndarray, least: int, step: int = 8) -> tuple[int, int, int, int] | None:
    """The largest (x, y, w, h) of ``used`` (H, W) bool holding none of it, sides at least
    ``least``, aspect 0.66-1.8; None when there is none."""
    H, W = used.shape
    ii = np.pad(used.cumsum(0).cumsum(1), ((1, 0), (1, 0)))

    def place(w: int, h: int) -> tuple[int, int] | None:
        for y in range(0, H - h + 1, step):
            for x in range(0, W - w + 1, step):
                if ii[y + h, x + w] - ii[y, x + w] - ii[y + h, x] + ii[y, x] == 0:
                    return x, y
        return None

    best = None
    for h in range(least, H + 1, step):
        for w in range(least, W + 1, step):
            if 0.66 <= w / h <= 1.8 and (best is None or w * h > best[2] * best[3]):
                at = place(w, h)
                if at is not None:
                    best = (*at, w, h)
    return best


def make(out: Path, scenes: Path | None, count: int) -> None:
    clips = out / "clips"
    for video in sorted(p for p in DAVIS.iterdir() if p.is_dir()):
        used = None
        for a in sorted((video / "Annotations").glob("*.png")):
            m = cv2.imread(str(a), cv2.IMREAD_GRAYSCALE) > 0
            used = m if used is None else used | m
        used = cv2.dilate(used.astype(np.uint8), np.ones((41, 41), np.uint8)) > 0
        box = free_window(used, 160)
        print(video.name, box, flush=True)
        if box is None:
            continue
        x, y, w, h = box
        dst = clips / f"neg-{video.name}"
        dst.mkdir(parents=True, exist_ok=True)
        for f in sorted((video / "JPEGImages").glob("*.jpg")):
            cv2.imwrite(
                str(dst / f.name), cv2.imread(str(f))[y : y + h, x : x + w], [cv2.IMWRITE_JPEG_QUALITY, 95]
            )
    if scenes is None:
        return
    from zooctl.benchdata.appearance import world_backgrounds

    tracks = sorted(p for p in scenes.iterdir() if (p / "video.npz").is_file())[::3][:count]
    for k, video in enumerate(tracks):
        z = np.load(video / "video.npz")
        frames = world_backgrounds(
            np.random.default_rng(1000 + k), z["intrinsics"], z["gt_cam_rotation"], z["masks"].shape[1:]
        )
        dst = clips / f"syn-scene{k}"
        dst.mkdir(parents=True, exist_ok=True)
        for i, f in enumerate(frames):
            cv2.imwrite(str(dst / f"{i:05d}.jpg"), f[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 95])
        print(dst.name, video.name, flush=True)


def collect(out: Path, videos: list[Path], davis: bool) -> None:
    from zooctl.paths import default_store
    from zooctl.store.video_reader import StoredVideo
    from zooctl.store.videos import VideoStore

    sources = [(p.name, p) for p in sorted((out / "clips").iterdir())]
    if davis:
        sources += [(f"jpeg-{p.name}", p / "JPEGImages") for p in sorted(DAVIS.iterdir()) if p.is_dir()]
    for folder in videos:
        sources += [
            (f"{folder.name}-{p.name}", p / "video.mp4")
            for p in sorted(folder.iterdir())
            if (p / "video.mp4").is_file()
        ]
    store = VideoStore(default_store())
    lines = []
    for name, src in sources:
        if not store.exists(name):
            cmd = [sys.executable, "-m", "zooctl", "video", "add", str(src), "--name", name]
            subprocess.run(cmd, check=True, capture_output=True, env=dict(os.environ))
        check = (StoredVideo(store.path(name)).segmenter or {}).get("animal_check")
        row = {"name": name, "animal": not name.startswith(("neg-", "syn-")), **(check or {})}
        lines.append(json.dumps(row))
        print(lines[-1], flush=True)
    (out / "checks.jsonl").write_text("\n".join(lines) + "\n")


def _warns(r: dict, rule: tuple) -> bool:
    regions, looks, empty = rule
    return (r["regions"] or 0) >= regions and (r["looks"] < looks or r["empty_share"] > empty)


def _cost(rows: list[dict], rule: tuple) -> tuple[float, int, int]:
    pos = [r for r in rows if r["animal"]]
    neg = [r for r in rows if not r["animal"]]
    false_warnings = sum(_warns(r, rule) for r in pos)
    misses = sum(not _warns(r, rule) for r in neg)
    return false_warnings / len(pos) + misses / len(neg), false_warnings, misses


def fit_rule(rows: list[dict]) -> tuple:
    """The grid's best rule: the most common regions and empty share among the best, and the
    middle of their best looks."""
    scored = [(_cost(rows, rule)[0], rule) for rule in itertools.product(REGIONS, LOOKS, EMPTY)]
    best = min(c for c, _ in scored)
    top = [rule for c, rule in scored if c <= best + 1e-12]
    regions = Counter(r[0] for r in top).most_common(1)[0][0]
    top = [r for r in top if r[0] == regions]
    empty = max(set(r[2] for r in top), key=lambda e: (sum(r[2] == e for r in top), -abs(e - 0.3)))
    looks = float(np.median([r[1] for r in top if r[2] == empty]))
    return regions, looks, empty


def choose(out: Path) -> None:
    rows = [json.loads(line) for line in (out / "checks.jsonl").read_text().splitlines() if line.strip()]
    for r in rows:
        n = r["name"]
        r["group"] = n.split("-", 1)[1] if n.startswith(("jpeg-", "neg-")) else n
    rule = fit_rule(rows)
    cost, fw, miss = _cost(rows, rule)
    pos, neg = sum(r["animal"] for r in rows), sum(not r["animal"] for r in rows)
    print(
        f"in-sample rule (regions >= {rule[0]}, looks < {rule[1]}, empty share > {rule[2]}): "
        f"{fw} false warnings of {pos} videos of an animal, {miss} misses of {neg} without"
    )
    wrong, rules = [], []
    for g in sorted(set(r["group"] for r in rows)):
        q = fit_rule([r for r in rows if r["group"] != g])
        rules.append(q)
        wrong += [(r["name"], q) for r in rows if r["group"] == g and _warns(r, q) != (not r["animal"])]
    fw = sum(1 for n, _ in wrong if not n.startswith(("neg-", "syn-")))
    print(f"leave-one-out: {fw} false warnings of {pos}, {len(wrong) - fw} misses of {neg}; wrong: {wrong}")
    print("rules chosen in the folds:", Counter(rules).most_common(4))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    m = sub.add_parser("make")
    m.add_argument("out", type=Path)
    m.add_argument("--scenes", type=Path)
    m.add_argument("--count", type=int, default=10)
    c = sub.add_parser("collect")
    c.add_argument("out", type=Path)
    c.add_argument("--videos", type=Path, nargs="*", default=[])
    c.add_argument("--davis", action="store_true")
    h = sub.add_parser("choose")
    h.add_argument("out", type=Path)
    args = ap.parse_args()
    if args.cmd == "make":
        make(args.out, args.scenes, args.count)
    elif args.cmd == "collect":
        collect(args.out, args.videos, args.davis)
    else:
        choose(args.out)


if __name__ == "__main__":
    main()
