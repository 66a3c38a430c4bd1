"""CASA fit benchmark: speed (60 frames, 320 px, ~4,000-vertex template) and quality (bench run).

    python bench/fit.py speed [--preset fast|quality] [--device cpu|cuda] [--repeat N] [--threads N] [--config FIT.json]
    python bench/fit.py quality [--assets N] [--frames 60] [--size 320] [--ablation ...]
    python bench/fit.py davis [--store DIR] [--videos dog cows blackswan] [--masks given auto]
        [--template VIDEO=ASSET ...] [--config FIT.json]
    python bench/fit.py length [--frames 240] [--short 60] [--asset Fox] [--template Wolf] [--whole]
        [--config FIT.json]

``speed`` renders one 60-frame 320x320 video of a shared Quaternius animal, fits it with another
animal as the template (`zooctl fit --template`, a fresh process, retrieval excluded only when
no index exists) and reports the wall time. ``quality`` renders videos from the shared assets,
adds them all to a scratch bank and runs `zooctl bench run` (each video's own asset excluded).
``davis`` fits the shared DAVIS videos (added to the video store the way `zooctl fit PATH`
does) with their given masks (``given``), with automatic GrabCut masks seeded by the first
annotation's box (``auto``) and with the default automatic masks of its frames alone, no box, as a
user's `zooctl fit FRAMES` makes them (``default``), and reports the reprojected mask IoU against
the DAVIS annotations (the ground truth in every case); the focal is what `zooctl fit` takes
(`zooctl.fit.focal`: no lens recorded, so ``camera.focal_guess``). The template comes from retrieval over a bank of the 28 shared assets unless
``--template VIDEO=ASSET`` says otherwise (then at the named template's joint rate, as `zooctl fit
--template` fits); ``--config`` is a fit config applied on top of the preset, as `zooctl fit --config`.
``length`` renders one long clip (the asset playing its own clips) and fits it whole and its
first ``--short`` frames alone (`fit_video`, the fast preset, the same template), then compares
the two fits on the frames both cover: the 3D metrics on 8 frames spread over them and the mask
IoU against the rendered (true) masks; with CPU seconds and the stage iterations each ran. The
long fits' metrics over all their frames too (``all_frames``). ``--whole`` adds the long clip fitted
at once (``window_frames`` 0) beside the default windows.
Results: print a markdown line for BENCHMARKS.md (machine, command, median).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import SHARED, machine  # noqa: E402

ASSETS = SHARED / "assets" / "quaternius"


# Passed on to zooctl when set: thread counts, and PYTHONPATH (to time another checkout's code,
# e.g. a `git worktree` of an older commit, with this virtualenv).
PASSED_ENV = ("OMP_NUM_THREADS", "ZOOCTL_TORCH_THREADS", "PYTHONPATH")


def zooctl(*args: str, store: Path, threads: int | None = None) -> subprocess.CompletedProcess:
    exe = Path(sys.executable).with_name("zooctl")
    env = {"ZOOCTL_STORE": str(store), "PATH": "/usr/bin:/bin"}
    env |= {k: os.environ[k] for k in PASSED_ENV if k in os.environ}
    if threads is not None:
        env["OMP_NUM_THREADS"] = str(threads)
    return subprocess.run([str(exe), *args], capture_output=True, text=True, env=env)


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def speed(args) -> None:
    with tempfile.TemporaryDirectory() as d:
        store, vids = Path(d) / "store", Path(d) / "videos"
        fox, wolf = ASSETS / "animals_pack" / "Fox.glb", ASSETS / "animals_pack" / "Wolf.glb"
        zooctl("bank", "add", str(fox), str(wolf), store=store)
        zooctl(
            "bench",
            "make",
            "--out",
            str(vids),
            "--asset",
            "Fox",
            "--frames",
            str(args.frames),
            "--size",
            str(args.size),
            store=store,
        )
        times, cpu, stage2 = [], [], []
        for i in range(args.repeat):
            t, c = time.perf_counter(), _children_cpu()
            p = zooctl(
                "fit",
                str(vids / "Fox"),
                "--template",
                "Wolf",
                "--preset",
                args.preset,
                "--device",
                args.device,
                "--name",
                f"s{i}",
                "--json",
                *(["--config", args.config] if args.config else []),
                store=store,
                threads=args.threads,
            )
            times.append(time.perf_counter() - t)
            cpu.append(_children_cpu() - c)
            if p.returncode != 0:
                sys.exit(p.stderr)
            rec = json.loads(p.stdout)
            stage2.append(rec["timings"].get("stage2", float("nan")))
        med = lambda xs: sorted(xs)[len(xs) // 2]  # noqa: E731
        threads = os.environ.get("OMP_NUM_THREADS", "default") if args.threads is None else args.threads
        config = f", --config {Path(args.config).name}" if args.config else ""
        peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024  # KiB on Linux
        print(
            f"| {machine()} | zooctl fit (Fox video {args.frames}x{args.size}px, template Wolf 3,994 vertices, --preset {args.preset}{config}, {args.device}, threads {threads}) | "
            f"median {med(times):.1f} s of {args.repeat} ({', '.join(f'{x:.1f}' for x in times)}), "
            f"CPU {med(cpu):.1f} s, stage 2 {med(stage2):.1f} s ({', '.join(f'{x:.1f}' for x in stage2)}), "
            f"peak RSS of a process {peak:.0f} MB | "
            f"mask IoU {rec['metrics']['mask_iou']:.3f}, mIoU {rec['metrics'].get('miou')} |"
        )
        print(json.dumps(rec["timings"]))


def quality(args) -> None:
    glbs = sorted(ASSETS.glob("*/*.glb"))[: args.assets]
    with tempfile.TemporaryDirectory() as d:
        store, vids = Path(d) / "store", Path(d) / "videos"
        zooctl("bank", "add", *map(str, sorted(ASSETS.glob("*/*.glb"))), store=store)
        names = [p.stem for p in glbs]
        zooctl(
            "bench",
            "make",
            "--out",
            str(vids),
            "--frames",
            str(args.frames),
            "--size",
            str(args.size),
            *sum((["--asset", n] for n in names), []),
            store=store,
        )
        extra = sum((["--ablation", a] for a in args.ablation), [])
        t = time.perf_counter()
        p = zooctl("bench", "run", str(vids), "--preset", args.preset, *extra, store=store)
        print(p.stdout or p.stderr)
        print(f"machine: {machine()}; {len(glbs)} videos; total {time.perf_counter() - t:.0f} s")


def davis(args) -> None:
    import numpy as np

    from zooctl.fit.config import load_config
    from zooctl.fit.focal import resolve_focal
    from zooctl.fit.job import load_source
    from zooctl.fit.named_start import template_start
    from zooctl.fit.run import fit_video, input_mask_iou
    from zooctl.fit.template import select_template
    from zooctl.store.bank import Bank

    store = Path(args.store) if args.store else Path(tempfile.mkdtemp()) / "store"
    bank = Bank(store)
    if not bank.names():
        zooctl("bank", "add", *map(str, sorted(ASSETS.glob("*/*.glb"))), store=store)
        bank = Bank(store)
    fixed = dict(t.split("=", 1) for t in args.template)
    print(f"machine: {machine()}; preset {args.preset}; store {store}")
    print("| video | masks | frames | template (top 3 retrieval) | start | IoU vs annotations | wall s |")
    print("|---|---|---|---|---|---|---|")
    for name in args.videos:
        folder = SHARED / "videos" / name
        first = _first_annotation(folder)  # original pixels, as `--box` takes them
        ys, xs = np.nonzero(first)
        box = (float(xs.min()), float(ys.min()), float(np.ptp(xs) + 1), float(np.ptp(ys) + 1))
        for kind in args.masks:
            t = time.perf_counter()
            cfg = load_config(Path(args.config) if args.config else None, args.preset).validate()
            if name in fixed:
                cfg = cfg.for_named_template()
            cfg.max_frames = args.max_frames
            video = load_source(
                str(folder / "JPEGImages") if kind == "default" else str(folder),
                store,
                "auto" if kind == "auto" else None,
                args.max_frames,
                box if kind == "auto" else None,
            )
            cfg, _ = resolve_focal(cfg, video)  # the focal `zooctl fit` would use (`camera.focal_guess`)
            asset, cands, trial, _ = select_template(bank, fixed.get(name), video, cfg)
            if trial is None:  # as `zooctl fit` starts a template given or left after the trials
                kept = template_start(video, asset, cfg, name in fixed)
                trial = None if kept is None else kept.state
                view = {} if kept is None else kept.view or {}
                start = view.get("start_trial", {}).get("kept", "greedy") + "/" + view.get("start", "search")
            else:
                picked = [c for c in cands if c.get("name") == asset.name]
                start, view = "trials", (picked[0].get("view_trial") or {}) if picked else {}
            if view.get("elevation_deg") is not None:  # the search's view of the animal, degrees above it
                start += f" {view['elevation_deg']:+.0f} deg"
            res = fit_video(video, asset, cfg, resume=trial)
            wall = time.perf_counter() - t
            H, W = video.size
            gt = _gt_masks(folder, store, video, (H, W))
            iou = float(np.nanmean(input_mask_iou(res, gt)))
            top = (
                ", ".join(
                    f"{c['name']} {c['score']:.2f}"
                    + (f" trial IoU {c['trial_iou']:.3f}" if "trial_iou" in c else "")
                    for c in cands[:3]
                )
                or "fixed"
            )
            print(
                f"| {name} | {kind} | {video.num_frames} | {asset.name} ({top}) | {start} | {iou:.3f} | {wall:.0f} |",
                flush=True,
            )


def _first_annotation(folder: Path):
    import numpy as np
    from PIL import Image

    from zooctl.video.decode import image_files

    with Image.open(image_files(folder / "Annotations")[0]) as im:
        return np.asarray(im.convert("L")) > 0


def _gt_masks(folder: Path, store: Path, video, size: tuple[int, int]):
    """The DAVIS annotations for the stored frames of ``video`` (their source indices)."""
    from zooctl.fit.inputs import _read_mask_folder
    from zooctl.store.videos import VideoStore

    rec = VideoStore(store).get(video.source[len("video:") :], what=())
    return _read_mask_folder(folder / "Annotations", rec.source_indices[: video.num_frames], size)


def length(args) -> None:
    import resource

    import numpy as np

    from zooctl.fit.config import load_config
    from zooctl.fit.inputs import load_fit_video
    from zooctl.fit.metrics import evaluate_fit
    from zooctl.fit.run import fit_video, input_mask_iou
    from zooctl.store.bank import Bank

    def cpu() -> float:
        ru = resource.getrusage(resource.RUSAGE_SELF)
        return ru.ru_utime + ru.ru_stime

    with tempfile.TemporaryDirectory() as d:
        store, vids = Path(d) / "store", Path(d) / "videos"
        glbs = [next(ASSETS.glob(f"*/{n}.glb")) for n in (args.asset, args.template)]
        zooctl("bank", "add", *map(str, glbs), store=store)
        zooctl("bench", "make", "--out", str(vids), "--asset", args.asset, "--frames", str(args.frames),
               "--size", str(args.size), "--motion", "clips", "--seed", str(args.seed), store=store)  # fmt: skip
        video = load_fit_video(vids / args.asset)
        template = Bank(store).get(args.template)
        rows = {}
        runs = [("short", video.truncated(args.short), None), ("long", video, None)]
        runs += [("long_whole", video, 0)] if args.whole else []
        for label, v, window_frames in runs:
            cfg = load_config(Path(args.config) if args.config else None, "fast").for_named_template()
            if window_frames is not None:
                cfg.window_frames = window_frames
            t, c = time.perf_counter(), cpu()
            res = fit_video(v, template, cfg)
            wall, cpu_s = time.perf_counter() - t, cpu() - c
            m = evaluate_fit(res, frames=8, reanimate_iters=0, within=args.short)
            iou_all = input_mask_iou(res)  # bench masks are the rendered truth
            iou = iou_all[: args.short]
            if label != "short":  # the whole clip too, over 8 frames spread over all of it
                whole = evaluate_fit(res, frames=8, reanimate_iters=0)
                whole = {k: whole[k] for k in ("miou", "joint", "novel_view_iou")}
                whole["mask_iou"] = float(np.nanmean(iou_all))
            rows[label] = {
                "frames": v.num_frames,
                "iters": [len(res.history["stage1"]), len(res.history["stage2"])],
                "wall_s": round(wall, 1),
                "cpu_s": round(cpu_s, 1),
                "mask_iou": round(float(np.nanmean(iou)), 4),
                **{k: round(float(m[k]), 4) for k in ("miou", "mcham", "joint", "skinning")},
                "novel_view_iou": None if m["novel_view_iou"] is None else round(m["novel_view_iou"], 4),
            }
            if label != "short":
                rows[label]["all_frames"] = {
                    k: None if x is None else round(float(x), 4) for k, x in whole.items()
                }
            print(label, json.dumps(rows[label]), flush=True)
        s, lg = rows["short"], rows["long"]
        keys = ("mask_iou", "miou", "novel_view_iou", "joint", "mcham")
        print(
            f"| {machine()} | {args.asset} {args.frames} frames x {args.size} px, template {args.template}, fast | "
            + " | ".join(f"{k} {s[k]} -> {lg[k]}" for k in keys)
            + f" | wall {s['wall_s']} -> {lg['wall_s']} s, CPU {s['cpu_s']} -> {lg['cpu_s']} s |"
        )


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("speed")
    s.add_argument("--preset", default="fast")
    s.add_argument("--device", default="cpu")
    s.add_argument("--frames", type=int, default=60)
    s.add_argument("--size", type=int, default=320)
    s.add_argument("--repeat", type=int, default=1)
    s.add_argument("--threads", type=int, default=None, help="torch threads of each fit (OMP_NUM_THREADS)")
    s.add_argument(
        "--config", default=None, help="a fit config (JSON) on top of the preset, as `zooctl fit --config`"
    )
    q = sub.add_parser("quality")
    q.add_argument("--assets", type=int, default=28)
    q.add_argument("--frames", type=int, default=60)
    q.add_argument("--size", type=int, default=320)
    q.add_argument("--preset", default="fast")
    q.add_argument("--ablation", action="append", default=[])
    dv = sub.add_parser("davis")
    dv.add_argument("--store", default=None, help="store with the bank (default: a new one, 28 assets)")
    dv.add_argument("--videos", nargs="+", default=["dog", "cows", "blackswan"])
    dv.add_argument("--masks", nargs="+", default=["given", "auto"], choices=["given", "auto", "default"])
    dv.add_argument("--template", action="append", default=[], help="VIDEO=ASSET instead of retrieval")
    dv.add_argument("--preset", default="fast")
    dv.add_argument("--config", default=None, help="a fit config (JSON) on top of the preset")
    dv.add_argument("--max-frames", type=int, default=60)
    ln = sub.add_parser("length")
    ln.add_argument("--frames", type=int, default=240)
    ln.add_argument("--short", type=int, default=60)
    ln.add_argument("--size", type=int, default=320)
    ln.add_argument("--asset", default="Fox")
    ln.add_argument("--template", default="Wolf")
    ln.add_argument("--seed", type=int, default=0)
    ln.add_argument("--whole", action="store_true", help="also fit the long clip at once (window_frames 0)")
    ln.add_argument("--config", default=None, help="a fit config (JSON) on top of the fast preset")
    a = ap.parse_args()
    {"speed": speed, "quality": quality, "davis": davis, "length": length}[a.cmd](a)
