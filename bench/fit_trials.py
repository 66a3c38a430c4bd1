"""The template trials' scores along the way, and a pruning rule for them chosen leave-one-video-out.

    python bench/fit_trials.py log DIR --store STORE --out LOG.jsonl [--part I/N] [--at 0 25 50 100]
    python bench/fit_trials.py choose LOG.jsonl [LOG2.jsonl ...]

``log`` runs, for every benchmark video of DIR (made by `zooctl bench make`; its own asset
excluded from retrieval, as `zooctl bench run` does), the template trials of ``--preset fast``
the way `zooctl.fit.template.try_candidates` does, but pauses each candidate's trial at every
stage-2 iteration of ``--at`` and at ``trials.iters``, resuming from the pause (which continues
the same fit: `fit_video`'s ``pause_at`` / ``resume``). Per candidate it writes the trial IoU and
the pick's score (trial IoU + the semantic term, as `pick_trial`) at each checkpoint, and the CPU
and wall seconds of the camera search, stage 1 and each stretch of stage-2 iterations. One JSON
line per video, appended as each finishes (``--part 1/2`` and ``2/2`` split the videos between
two processes).

``choose`` scores pruning rules (checkpoint c, margin m: after c stage-2 iterations a candidate
whose score is more than m below the best stops; the rest go on to ``trials.iters``) on the
logged videos: does the rule keep the template the full trials pick, and what share of the
trials' CPU time does it save. The rule is chosen on all videos (in-sample) and leave-one-video-
out (chosen on the others, scored on the held-out one): the rule saving the most time among
those that keep every pick of the videos it is chosen on.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import add_log_parser, machine, videos_to_log  # noqa: E402

MARGINS = (0.0, 0.005, 0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.08, 0.1, 0.15, 0.2)


def _clock() -> tuple[float, float]:
    return time.perf_counter(), time.process_time()


def log(args) -> None:
    from zooctl.benchdata.run import _own_asset
    from zooctl.fit.config import preset
    from zooctl.fit.job import load_source
    from zooctl.fit.run import fit_video
    from zooctl.fit.template import TRIAL_SEMANTIC_WEIGHT, choose_template, pick_trial, trial_score
    from zooctl.fit.view_trial import trial_iou
    from zooctl.store.bank import Bank

    store = Path(args.store)
    bank = Bank.open(store)
    out = Path(args.out)
    vids = videos_to_log(args.folder, args.part, out)
    for v in vids:
        cfg = preset("fast").for_trials()  # the trials' own shape rate, as try_candidates
        stops = sorted({a for a in args.at if a < cfg.trials.iters} | {cfg.trials.iters})
        video = load_source(str(v), store, None, cfg.max_frames)
        own = _own_asset(v)
        t, c = _clock()
        _, cands = choose_template(
            bank, None, video.frames, video.masks, exclude={own}, trials=cfg.trials.candidates
        )
        retrieval = {"wall": time.perf_counter() - t, "cpu": time.process_time() - c}
        rows = []
        for cand in cands[: cfg.trials.candidates]:
            asset = bank.get(cand["name"])
            sem = float(cand.get("semantic") or 0.0)
            state, seg, prev = None, [], 0
            for stop in stops:
                t, c = _clock()
                res = fit_video(video, asset, cfg, resume=state, pause_at=stop)
                wall, cpu = time.perf_counter() - t, time.process_time() - c
                iou = trial_iou(res)
                tm = res.timings
                seg.append(
                    {
                        "at": stop,
                        "iters": stop - prev,
                        "iou": round(iou, 5),
                        "score": round(iou + TRIAL_SEMANTIC_WEIGHT * sem, 5),
                        "wall": round(wall, 3),
                        "cpu": round(cpu, 3),
                        "camera": round(tm.get("camera", 0.0), 3) if state is None else None,
                        "stage1": round(tm.get("stage1", 0.0), 3) if state is None else None,
                    }
                )
                state, prev = res.paused, stop
            rows.append({"name": cand["name"], "semantic": sem, "checkpoints": seg})
        final = [r["checkpoints"][-1]["iou"] for r in rows]
        # the displacement term of `trial_score` is not logged here: the rule before it
        pick = pick_trial([trial_score(i, r["semantic"]) for i, r in zip(final, rows)], cfg.trials.margin)
        line = {
            "video": v.name,
            "asset": own,
            "retrieval": retrieval,
            "candidates": rows,
            "pick": rows[pick]["name"],
            "trial_iters": cfg.trials.iters,
            "machine": machine(),
            "load": os.getloadavg()[0],
        }
        with out.open("a") as f:
            f.write(json.dumps(line) + "\n")
        print(v.name, line["pick"], [(r["name"], r["checkpoints"][-1]["iou"]) for r in rows], flush=True)


def _outcome(video: dict, at: int, margin: float) -> tuple[bool, float, float]:
    """(the full trials' pick kept, trial CPU seconds saved, trial CPU seconds in all) for the rule
    (prune after ``at`` stage-2 iterations by ``margin``) on one logged video."""
    cands = video["candidates"]
    total = sum(s["cpu"] for c in cands for s in c["checkpoints"])

    def score(c: dict) -> float:
        return next(s["score"] for s in c["checkpoints"] if s["at"] == at)

    best = max(score(c) for c in cands)
    kept, saved = True, 0.0
    for c in cands:
        if score(c) < best - margin:  # pruned: the iterations after the checkpoint are not run
            saved += sum(s["cpu"] for s in c["checkpoints"] if s["at"] > at)
            kept = kept and c["name"] != video["pick"]
    return kept, saved, total


def _choose(videos: list[dict], rules: list[tuple[int, float]]) -> tuple[int, float]:
    """The rule saving the most CPU time among those keeping every pick of ``videos`` (ties: the
    later checkpoint, then the larger margin: the more cautious)."""
    best = None
    for at, m in rules:
        res = [_outcome(v, at, m) for v in videos]
        if not all(k for k, _, _ in res):
            continue
        key = (sum(s for _, s, _ in res), at, m)
        if best is None or key > best[0]:
            best = (key, (at, m))
    return best[1]


def choose(args) -> None:
    videos = [
        json.loads(line) for p in args.logs for line in Path(p).read_text().splitlines() if line.strip()
    ]
    videos.sort(key=lambda v: v["video"])
    stops = sorted({s["at"] for s in videos[0]["candidates"][0]["checkpoints"]})
    rules = [(a, m) for a in stops[:-1] for m in MARGINS]
    print(f"{len(videos)} videos; checkpoints {stops}")
    # where the trials' time goes: wall and CPU seconds; the first stretch's CPU (camera search,
    # stage 1, its stage-2 iterations) is shared out in proportion to their wall seconds
    wall: dict[str, float] = {"camera search": 0.0, "stage 1": 0.0}
    cpu: dict[str, float] = dict(wall)
    for v in videos:
        for c in v["candidates"]:
            for s in c["checkpoints"]:
                key = f"stage 2, iterations {s['at'] - s['iters']}-{s['at']}"
                parts = {key: s["wall"]}
                if s["camera"] is not None:
                    parts = {
                        "camera search": s["camera"],
                        "stage 1": s["stage1"],
                        key: max(s["wall"] - s["camera"] - s["stage1"], 0.0),
                    }
                for k, x in parts.items():
                    wall[k] = wall.get(k, 0.0) + x
                    cpu[k] = cpu.get(k, 0.0) + s["cpu"] * x / max(s["wall"], 1e-9)
    total_wall, total_cpu = sum(wall.values()), sum(cpu.values())
    print(f"trials: wall {total_wall:.0f} s, CPU {total_cpu:.0f} s over {len(videos)} videos")
    for k in wall:
        print(
            f"  {k}: wall {wall[k]:.0f} s ({wall[k] / total_wall:.1%}), CPU {cpu[k]:.0f} s ({cpu[k] / total_cpu:.1%})"
        )
    print("\nrule (checkpoint, margin): picks kept of N, CPU saved of the trials'")
    for at, m in rules:
        res = [_outcome(v, at, m) for v in videos]
        kept = sum(k for k, _, _ in res)
        saved = sum(s for _, s, _ in res) / sum(t for _, _, t in res)
        print(f"  {at:4d} {m:5.3f}: {kept}/{len(videos)} kept, {saved:.1%} saved")
    rule = _choose(videos, rules)
    res = [_outcome(v, *rule) for v in videos]
    print(
        f"\nin-sample rule {rule}: {sum(k for k, _, _ in res)}/{len(videos)} picks kept, "
        f"{sum(s for _, s, _ in res) / sum(t for _, _, t in res):.1%} of the trials' CPU saved"
    )
    loo, chosen = [], []
    for i, v in enumerate(videos):
        r = _choose(videos[:i] + videos[i + 1 :], rules)
        chosen.append(r)
        loo.append(_outcome(v, *r))
        print(f"  held out {v['video']}: rule {r}, pick kept {loo[-1][0]}, saved {loo[-1][1]:.0f} s")
    print(
        f"leave-one-video-out: {sum(k for k, _, _ in loo)}/{len(videos)} picks kept, "
        f"{sum(s for _, s, _ in loo) / sum(t for _, _, t in loo):.1%} of the trials' CPU saved; "
        f"rules chosen {sorted(set(chosen))}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    lg = add_log_parser(sub)
    lg.add_argument("--at", type=int, nargs="+", default=[0, 25, 50, 100])
    ch = sub.add_parser("choose")
    ch.add_argument("logs", nargs="+")
    args = ap.parse_args()
    log(args) if args.cmd == "log" else choose(args)


if __name__ == "__main__":
    main()
