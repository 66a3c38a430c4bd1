"""How many seed frames `animalnet` should try, and by what lead another seed's masks replace the
first's: every seed's masks measured once, the choices scored leave-one-video-out.

    ZOOCTL_STORE=S python bench/seed_choice.py collect OUT [--davis VARIANT...] [--bench DIR...]
    python bench/seed_choice.py choose OUT [--json RESULT]

``collect`` stores each video by `zooctl video add` (in this process, ``--seg-option seeds=3``)
and keeps, for every seed tried, its masks at the working size (steps 1-6 of
`zooctl.video.animalnet.AnimalNetSegmenter`, before the colour snap and the upsample), their
agreement with the network's animal (`network_agreement`, the number the choice reads) and their J
against the truth at that size: ``OUT/SET-VIDEO.json``. ``--davis``: the seven shared DAVIS
videos as the variants of `video_variants.py` (jpeg, h264, mirror; made in OUT/work); ``--bench``:
the `zooctl bench make` videos of DIR (their ``video.mp4``, set named after DIR).

``choose`` scores, for 1, 2 and 3 seeds, the margin (lead over the first seed's agreement that
another seed needs) chosen on a grid as the one with the largest mean J gain over one seed, each
set weighing alike, among margins under which no set's mean J falls; and leave-one-video-out, each
video scored with the margin chosen on the others (a DAVIS video's variants left out together).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import cv2
import numpy as np
from _util import SHARED
from video_variants import VARIANTS, variant_source

GRID = [round(float(x), 3) for x in np.arange(0.0, 0.2001, 0.005)]


def _at(truth: np.ndarray, h: int, w: int) -> np.ndarray:
    return np.stack(
        [cv2.resize(t.astype(np.float32), (w, h), interpolation=cv2.INTER_AREA) > 0.5 for t in truth]
    )


def collect(out: Path, davis: list[str], benches: list[Path]) -> None:
    from zooctl.cli.main import run
    from zooctl.fit.inputs import _read_mask_folder, load_fit_video
    from zooctl.paths import default_store
    from zooctl.store.videos import VideoStore
    from zooctl.video import animalnet
    from zooctl.video.mask_quality import per_frame_j

    seen: list[tuple] = []
    decide = animalnet.AnimalNetSegmenter.decide_near

    def recorded(self, small, prior, flow, *args, **kw):  # every seed's steps 1-6, as they ran
        masks = decide(self, small, prior, flow, *args, **kw)
        seen.append((kw.get("seed_frame"), np.asarray(masks, bool).copy(), kw.get("looks")))
        return masks

    animalnet.AnimalNetSegmenter.decide_near = recorded
    store = VideoStore(default_store())
    jobs = []
    work = out / "work"
    work.mkdir(parents=True, exist_ok=True)
    videos = sorted(p.name for p in (SHARED / "videos").iterdir() if (p / "Annotations").is_dir())
    for variant in davis:
        for v in videos:

            def truth(rec, v=v, variant=variant):
                t = _read_mask_folder(
                    SHARED / "videos" / v / "Annotations", rec.source_indices, rec.masks.shape[1:]
                )
                return t[:, :, ::-1] if variant == "mirror" else t

            jobs.append((variant, v, v, lambda v=v, variant=variant: variant_source(variant, v, work), truth))
    for folder in benches:
        for d in sorted(p for p in folder.iterdir() if (p / "video.npz").is_file()):
            jobs.append(
                (
                    folder.name,
                    d.name,
                    d.name,
                    lambda d=d: d / "video.mp4",
                    lambda rec, d=d: load_fit_video(d, max_size=100_000).masks,
                )
            )
    for set_name, name, group, source, truth_of in jobs:
        path = out / f"{set_name}-{name}.json"
        if path.exists():
            continue
        seen.clear()
        stored = f"seeds-{set_name}-{name}".lower()
        code = run(
            ["video", "add", str(source()), "--name", stored, "-q", "--replace", "--seg-option", "seeds=3"]
        )
        if code:
            sys.exit(f"video add of {name} failed ({code})")
        rec = store.get(stored, what=("masks",))
        truth = np.asarray(truth_of(rec), bool)
        looks = seen[0][2]
        h, w = seen[0][1].shape[1:]
        small_truth = _at(truth, h, w)
        seeds = [
            {
                "frame": int(k if k is not None else -1),
                "agreement": animalnet.network_agreement(m, looks),
                "j": float(np.mean(per_frame_j(m, small_truth))),
            }
            for k, m, _ in seen
        ]
        path.write_text(json.dumps({"set": set_name, "video": name, "group": group, "seeds": seeds}))
        print(
            set_name,
            name,
            " ".join(f"{s['frame']}:{s['agreement']:.3f}/{s['j']:.3f}" for s in seeds),
            flush=True,
        )


def _pick(seeds: list[dict], n: int, margin: float) -> float:
    tried = seeds[:n]
    best = max(range(len(tried)), key=lambda i: (tried[i]["agreement"], -i))
    return tried[best]["j"] if tried[best]["agreement"] - tried[0]["agreement"] > margin else tried[0]["j"]


def _set_means(rows: list[dict], n: int, margin: float) -> dict[str, float]:
    per: dict[str, list[float]] = {}
    for r in rows:
        per.setdefault(r["set"], []).append(_pick(r["seeds"], n, margin))
    return {k: float(np.mean(v)) for k, v in per.items()}


def _choose(rows: list[dict], n: int) -> float:
    if not rows:
        return 0.0
    base = _set_means(rows, 1, 0.0)
    allowed = [m for m in GRID if all(v >= base[k] - 1e-12 for k, v in _set_means(rows, n, m).items())]
    if not allowed:
        return float("inf")
    return max(allowed, key=lambda m: (np.mean([v - base[k] for k, v in _set_means(rows, n, m).items()]), -m))


def choose(out: Path, json_out: Path | None) -> None:
    rows = [json.loads(p.read_text()) for p in sorted(out.glob("*.json"))]
    if not rows:
        sys.exit(f"no collected videos in {out}: run `collect` first")
    sets = sorted({r["set"] for r in rows})
    result = {}
    print("| seeds | margin (in-sample) | " + " | ".join(f"{s} in-sample / LOO" for s in sets) + " |")
    print("|---|---:|" + "---:|" * len(sets))
    for n in (1, 2, 3):
        m = _choose(rows, n) if n > 1 else 0.0
        ins = _set_means(rows, n, m)
        loo: dict[str, list[float]] = {}
        for g in sorted({r["group"] for r in rows}):
            rest = [r for r in rows if r["group"] != g]
            mg = _choose(rest, n) if n > 1 else 0.0
            for r in rows:
                if r["group"] == g:
                    loo.setdefault(r["set"], []).append(_pick(r["seeds"], n, mg))
        looms = {k: float(np.mean(v)) for k, v in loo.items()}
        result[n] = {"margin": m, "in_sample": ins, "leave_one_out": looms}
        print(f"| {n} | {m} | " + " | ".join(f"{ins[s]:.3f} / {looms[s]:.3f}" for s in sets) + " |")
    if json_out:
        json_out.write_text(json.dumps(result, indent=1))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="what", required=True)
    c = sub.add_parser("collect")
    c.add_argument("out", type=Path)
    c.add_argument("--davis", nargs="*", choices=VARIANTS, default=[])
    c.add_argument("--bench", nargs="*", type=Path, default=[])
    s = sub.add_parser("choose")
    s.add_argument("out", type=Path)
    s.add_argument("--json", type=Path)
    args = ap.parse_args()
    if args.what == "collect":
        if args.davis and not (SHARED / "videos").is_dir():
            sys.exit(f"skipped: the shared DAVIS videos are not at {SHARED / 'videos'}")
        args.out.mkdir(parents=True, exist_ok=True)
        collect(args.out, args.davis, args.bench)
    else:
        choose(args.out, args.json)


if __name__ == "__main__":
    main()
