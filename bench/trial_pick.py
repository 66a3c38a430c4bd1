"""What the template trials could pick by: each candidate's trial scored in 3D, and pick rules
chosen leave-one-video-out (issue 50: the novel view with retrieved templates).

    python bench/trial_pick.py log DIR --store STORE --out LOG.jsonl [--part I/N] [--own-template] [--turned]
        [--carried] [--candidates N --skip-logged LOG.jsonl ...]
    python bench/trial_pick.py choose LOG.jsonl [LOG2.jsonl ...] [--finished RUN.json] [--candidates N]
        [--displacement W] [--spread W] [--best-start]

``log`` runs, for every benchmark video of DIR (`zooctl bench make`; its own asset excluded from
retrieval, as `zooctl bench run` does), the template trials of ``--preset fast`` as
`zooctl.fit.template.try_candidates` does (each candidate's fit paused after ``trials.iters``
stage-2 iterations), and for every candidate's trial writes its trial IoU, semantic score, the
benchmark's 3D metrics at the pause (`zooctl.fit.metrics.evaluate_fit`: novel view, mIoU, Joint)
and what the trial did to the template to get there: its joints' mean and 90th-percentile angle
from the rest pose, their frame-to-frame angle, the bones' stretch, the skinning weights' drift
(the KL of the skin prior), the displacement, every loss term over the last 25 steps, and, where
the camera's turn is read from the background, how the root turns in the world (`world_turn`) and
how its body, kept as posed at one frame, matches the masks of the frames the camera saw from 20
(``view_consistency``) or 45 degrees (``view_consistency_45``) away.
``--own-template``: each video's own asset the only candidate (fitted as a named template is,
from the search's start or its depth mirror: `trial_with_mirror`);
``--turned``: each candidate also tried from the camera search's best view at least 90 degrees of
azimuth from its pick (`fit_video`'s ``start="turned"``). ``--carried``: where the camera's turn is
read, each candidate also tried from the start carried by it (``camera.motion`` background), as
the fit's trials do by default (``trials.carried``; both starts logged to the trials' end, as
``trials.carried_at`` null compares them). ``--candidates N``: retrieval's first N
(the family's best moved up to the N-th place, as the fit does), less those ``--skip-logged``
logs hold.

``choose`` scores pick rules on the logged videos: the base rule (trial IoU + 0.1 x semantic, less
``--displacement`` W times the displacement: 0, the rule before the displacement term, by
default; 1.5 today's; less ``--spread`` W times the body's turn in the world, 0.016 today's),
the oracle (the best novel view among the tried), and that score less lambda x one feature
(``view_consistency``, `zooctl.fit.view_trial.trial_view_consistency`, is added: its lambdas are
negative), with lambda chosen on all videos (in-sample) and leave-one-video-out (chosen
on the others, scored on the held-out one), by the mean novel view at the trials' end.
``--best-start`` keeps, of each candidate's logged starts, the one the fit's trials keep: the
highest `zooctl.fit.template.trial_score` (the displacement at ``--displacement``, the turn in the
world at the shipped weight; the first logged on a tie).
``--finished`` (a `zooctl bench run --json` of the same videos) checks how well the trial's novel
view predicts the finished fit's. Logs of the same videos are merged, their candidates in the
logs' order; ``--candidates N`` keeps each video's first N.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import add_log_parser, machine, videos_to_log  # noqa: E402

FEATURES = (
    "pose_deg",
    "pose_p90_deg",
    "jitter_deg",
    "stretch",
    "skin_kl",
    "displacement",
    "loss_total",
    "loss_prior",
    "world_step_deg",
    "world_spread_deg",
    "view_consistency",
)
# a geometric grid per feature, from about a tenth to about ten times what a typical spread of the
# feature between candidates is worth in trial IoU (0.01)
LAMBDAS = {
    "pose_deg": tuple(0.01 / 2.0 * 2.0**k for k in range(-3, 5)),
    "pose_p90_deg": tuple(0.01 / 4.0 * 2.0**k for k in range(-3, 5)),
    "jitter_deg": tuple(0.01 / 0.3 * 2.0**k for k in range(-3, 5)),
    "stretch": tuple(0.01 / 0.01 * 2.0**k for k in range(-3, 5)),
    "skin_kl": tuple(0.01 / 0.05 * 2.0**k for k in range(-3, 5)),
    "displacement": tuple(0.01 / 0.01 * 2.0**k for k in range(-3, 5)),
    "loss_total": tuple(0.01 / 0.02 * 2.0**k for k in range(-3, 5)),
    "loss_prior": tuple(0.01 / 0.003 * 2.0**k for k in range(-3, 5)),
    "world_step_deg": tuple(0.01 / 0.5 * 2.0**k for k in range(-3, 5)),
    "world_spread_deg": tuple(0.01 / 5.0 * 2.0**k for k in range(-3, 5)),
    # higher is better: a negative lambda adds it
    "view_consistency": tuple(-0.25 * 2.0**k for k in range(6)),
}
PRIOR_TERMS = ("smooth", "symmetry", "bone_length", "skin", "displacement", "pose", "root_smooth", "scale")


def world_turn(res, follow: np.ndarray | None) -> dict[str, float]:
    """How the trial's root turns in the world, the camera's turn read from the background
    (``follow``, `zooctl.fit.run.trial_camera_turn`) taken out: the mean angle between consecutive
    frames (``world_step_deg``) and the mean angle of each frame from their mean orientation
    (``world_spread_deg``, `zooctl.fit.view_trial.trial_world_spread`, what the trials score by).
    NaN where the turn was not read (a camera at rest tells nothing)."""
    from zooctl.fit.view_trial import trial_world_spread
    from zooctl.geometry import quat_to_matrix, rotation_angle_deg

    if follow is None:
        return {"world_step_deg": float("nan"), "world_spread_deg": float("nan")}
    q = res.scene.root_rotation.detach().cpu().numpy().astype(np.float64)
    W = np.transpose(follow, (0, 2, 1)) @ quat_to_matrix(q / np.linalg.norm(q, axis=-1, keepdims=True))
    steps = [rotation_angle_deg(W[t + 1] @ W[t].T) for t in range(len(W) - 1)]
    spread = trial_world_spread({"scene": {"root_rotation": res.scene.root_rotation}}, follow)
    return {"world_step_deg": float(np.mean(steps)), "world_spread_deg": float(spread)}


def features(res) -> dict[str, float]:
    """What a trial did to its template to fit the video (module docstring)."""
    import torch

    from zooctl.fit.losses import skin_prior
    from zooctl.fit.view_trial import trial_displacement
    from zooctl.rig.rotations import quat_angle

    sc = res.scene
    with torch.no_grad():
        q = sc.rotations / sc.rotations.norm(dim=-1, keepdim=True)  # (T, J, 4)
        rest = sc.model.rest_rotation[None].expand_as(q)
        ang = torch.rad2deg(quat_angle(q, rest)).cpu().numpy()  # (T, J)
        step = torch.rad2deg(quat_angle(q[1:], q[:-1])).cpu().numpy()
        out = {
            "pose_deg": float(ang.mean()),
            "pose_p90_deg": float(np.percentile(ang, 90)),
            "jitter_deg": float(step.mean()),
            "stretch": float(sc.model.log_bone_scales.abs().mean()),
            "skin_kl": float(skin_prior(sc.model.skin.logits, sc.init_logits)),
        }
    out["displacement"] = trial_displacement(res)  # what `trial_score` takes off
    last = res.history.get("stage2", [])[-25:]
    keys = sorted({k for h in last for k in h})
    loss = {k: float(np.mean([h.get(k, 0.0) for h in last])) for k in keys}
    out["loss_total"] = loss.get("total", float("nan"))
    out["loss_prior"] = sum(loss.get(k, 0.0) for k in PRIOR_TERMS)
    out["loss"] = {k: round(v, 6) for k, v in loss.items()}
    return out


def log(args) -> None:
    from zooctl.benchdata.run import _own_asset
    from zooctl.fit.config import preset
    from zooctl.fit.job import load_source
    from zooctl.fit.metrics import evaluate_fit
    from zooctl.fit.run import fit_video, trial_camera_turn
    from zooctl.fit.template import carried_start_wanted, choose_template, trial_score
    from zooctl.fit.view_trial import trial_iou, trial_view_consistency, trial_with_mirror
    from zooctl.store.bank import Bank

    store = Path(args.store)
    bank = Bank.open(store)
    out = Path(args.out)
    vids = videos_to_log(args.folder, args.part, out)
    logged: dict[str, set[str]] = {}  # the candidates --skip-logged already has, by video
    for p in args.skip_logged or []:
        for line in Path(p).read_text().splitlines():
            if line.strip():
                row = json.loads(line)
                logged.setdefault(row["video"], set()).update(c["name"] for c in row["candidates"])
    for v in vids:
        cfg = preset("fast")
        video = load_source(str(v), store, None, cfg.max_frames)
        follow = trial_camera_turn(video, cfg)
        own = _own_asset(v)
        if args.own_template:  # the animal's own rig, as a named template is fitted
            cfg = cfg.for_named_template()
            cands = [{"name": own}]
        else:
            cfg.trials.candidates = args.candidates or cfg.trials.candidates
            cfg = cfg.for_trials()  # the trials' own shape rate, as try_candidates
            _, cands = choose_template(
                bank, None, video.frames, video.masks, exclude={own}, trials=cfg.trials.candidates
            )
            cands = [c for c in cands[: cfg.trials.candidates] if c["name"] not in logged.get(v.name, ())]
        starts = ("search", "turned") if args.turned else ("search",)
        if args.carried and not args.own_template and carried_start_wanted(video, cfg, follow):
            starts += ("carried",)
        rows = []
        for cand, start in ((c, s) for c in cands for s in starts):
            asset = bank.get(cand["name"])
            t, c = time.perf_counter(), time.process_time()
            kept = None
            if args.own_template and start == "search":
                # as `zooctl fit --template` starts: the search's start or its depth mirror
                kept = trial_with_mirror(video, asset, cfg, pause_at=cfg.trials.iters)
                res = fit_video(video, asset, cfg, resume=kept.state, pause_at=cfg.trials.iters)
            elif start == "carried":  # as the trials' Trial(motion="background")
                carried = cfg.with_camera_motion("background")
                res = fit_video(video, asset, carried, pause_at=cfg.trials.iters)
            else:
                res = fit_video(video, asset, cfg, pause_at=cfg.trials.iters, start=start)
            wall, cpu = time.perf_counter() - t, time.process_time() - c
            iou = trial_iou(res)
            sem = float(cand.get("semantic") or 0.0)
            m = evaluate_fit(res)
            rows.append(
                {
                    "name": cand["name"] if start == "search" else f"{cand['name']} ({start})",
                    "start": start if kept is None else kept.view["start"],
                    "semantic": sem,
                    "iou": round(iou, 5),
                    "score": round(trial_score(iou, sem), 5),  # the rule before the displacement term
                    "novel_view_iou": m["novel_view_iou"],
                    "miou": m["miou"],
                    "joint": m["joint"],
                    "features": features(res)
                    | world_turn(res, follow)
                    | {
                        "view_consistency": trial_view_consistency(res, follow),
                        "view_consistency_45": trial_view_consistency(res, follow, min_turn_deg=45.0),
                    },
                    "wall": round(wall, 2),
                    "cpu": round(cpu, 2),
                }
            )
        line = {
            "video": v.name,
            "asset": own,
            "candidates": rows,
            "trial_iters": cfg.trials.iters,
            "machine": machine(),
            "load": os.getloadavg()[0],
        }
        with out.open("a") as f:
            f.write(json.dumps(line) + "\n")
        print(
            v.name,
            [(r["name"], r["iou"], round(r["novel_view_iou"], 3)) for r in rows],
            flush=True,
        )


def _feature(c: dict, name: str) -> float:
    """A logged trial's feature, NaN where it was not measured (no camera turn read)."""
    x = c["features"].get(name)
    return float("nan") if x is None else float(x)


def _less_spread(c: dict, weight: float) -> float:
    """A logged trial's score less ``weight`` times its body's turn in the world, where measured."""
    spread = _feature(c, "world_spread_deg")
    return c["score"] - (weight * spread if np.isfinite(spread) else 0.0)


def _best_starts(candidates: list[dict]) -> list[dict]:
    """Each candidate's logged start that the fit's trials keep (module docstring, ``--best-start``),
    named as the candidate, in the order the candidates were first logged."""
    from zooctl.fit.view_trial import TRIAL_WORLD_SPREAD_WEIGHT

    best: dict[str, dict] = {}
    for c in candidates:  # c["score"] has the displacement term at --displacement already
        base = c["name"].split(" (")[0]
        if base not in best or _less_spread(c, TRIAL_WORLD_SPREAD_WEIGHT) > (
            _less_spread(best[base], TRIAL_WORLD_SPREAD_WEIGHT) + 1e-12
        ):
            best[base] = c | {"name": base, "logged_as": c["name"]}
    return list(best.values())


def _pick(video: dict, feature: str | None, lam: float) -> dict:
    """The candidate a rule picks: the highest trial IoU + 0.1 semantic - lam x feature (ties: the
    first in retrieval order, as `pick_trial`)."""

    def score(c: dict) -> float:
        x = _feature(c, feature) if feature else 0.0
        return c["score"] - (lam * x if np.isfinite(x) else 0.0)

    scores = [score(c) for c in video["candidates"]]
    return video["candidates"][int(np.argmax(scores))]


def _mean(videos: list[dict], feature: str | None, lam: float, key: str = "novel_view_iou") -> float:
    return float(np.mean([_pick(v, feature, lam)[key] for v in videos]))


def _choose_lam(videos: list[dict], feature: str) -> float:
    """The lambda (0 among them) with the best mean novel view on ``videos``; ties: the smaller."""
    best = (0.0, _mean(videos, feature, 0.0))
    for lam in LAMBDAS[feature]:
        m = _mean(videos, feature, lam)
        if m > best[1] + 1e-9:
            best = (lam, m)
    return best[0]


def choose(args) -> None:
    merged: dict[str, dict] = {}  # a video's candidates from every log, in the logs' order
    for p in args.logs:
        for line in Path(p).read_text().splitlines():
            if line.strip():
                row = json.loads(line)
                if row["video"] in merged:
                    merged[row["video"]]["candidates"] += row["candidates"]
                else:
                    merged[row["video"]] = row
    videos = sorted(merged.values(), key=lambda v: v["video"])
    for v in videos:  # the base rule: today's trial score, the displacement term at its weight
        for c in v["candidates"]:
            c["score"] -= args.displacement * c["features"]["displacement"]
    if args.best_start:
        for v in videos:
            v["candidates"] = _best_starts(v["candidates"])
    for v in videos:  # after the starts are kept: `_best_starts` weighs the spread itself
        for c in v["candidates"]:
            c["score"] = _less_spread(c, args.spread)
    if args.candidates:
        for v in videos:
            v["candidates"] = v["candidates"][: args.candidates]
    n = len(videos)
    print(f"{n} videos, {sum(len(v['candidates']) for v in videos)} trials")
    oracle = [max(v["candidates"], key=lambda c: c["novel_view_iou"]) for v in videos]
    print("| rule | in-sample novel view | LOO novel view | LOO mIoU | LOO Joint | LOO picks changed |")
    print("|---|---:|---:|---:|---:|---:|")
    today = [_pick(v, None, 0.0) for v in videos]
    f = lambda picks, k: np.mean([p[k] for p in picks])  # noqa: E731
    print(
        f"| base (trial IoU + 0.1 semantic - {args.displacement:g} displacement - {args.spread:g} spread) | {f(today, 'novel_view_iou'):.3f} | {f(today, 'novel_view_iou'):.3f} | {f(today, 'miou'):.3f} | {f(today, 'joint'):.3f} | 0 |"
    )
    print(
        f"| oracle (best novel view of the 3) | {f(oracle, 'novel_view_iou'):.3f} | | {f(oracle, 'miou'):.3f} | {f(oracle, 'joint'):.3f} | {sum(o is not t for o, t in zip(oracle, today))} |"
    )
    for feat in FEATURES:
        lam_in = _choose_lam(videos, feat)
        ins = [_pick(v, feat, lam_in) for v in videos]
        loo, lams = [], []
        for i, v in enumerate(videos):
            lam = _choose_lam(videos[:i] + videos[i + 1 :], feat)
            lams.append(lam)
            loo.append(_pick(v, feat, lam))
        changed = sum(p["name"] != t["name"] for p, t in zip(loo, today))
        print(
            f"| {feat} (in-sample lambda {lam_in:g}; LOO {[float(f'{x:.3g}') for x in sorted(set(lams))]}) | {f(ins, 'novel_view_iou'):.3f} "
            f"| {f(loo, 'novel_view_iou'):.3f} | {f(loo, 'miou'):.3f} | {f(loo, 'joint'):.3f} | {changed} |"
        )
    # the feature chosen too, with its lambda, on the other videos: what picking among the eight costs
    loo, chosen = [], []
    for i, v in enumerate(videos):
        rest = videos[:i] + videos[i + 1 :]
        best = max(
            ((feat, _choose_lam(rest, feat)) for feat in FEATURES),
            key=lambda fl: (_mean(rest, *fl), -FEATURES.index(fl[0])),
        )
        chosen.append(best)
        loo.append(_pick(v, *best))
    changed = sum(p["name"] != t["name"] for p, t in zip(loo, today))
    names = sorted({f"{fe} {lam:g}" for fe, lam in chosen})
    print(
        f"| any of the {len(FEATURES)} (feature and lambda chosen on the others: {names}) | "
        f"| {f(loo, 'novel_view_iou'):.3f} | {f(loo, 'miou'):.3f} | {f(loo, 'joint'):.3f} | {changed} |"
    )
    print("\nper video: today's pick / oracle; each candidate name: trial IoU, score, novel view, features")
    for v, t in zip(videos, today):
        print(f"{v['video']}: pick {t['name']} ({t['novel_view_iou']:.3f})")
        for c in v["candidates"]:
            print(
                f"   {c['name']:<16} iou {c['iou']:.3f} sem {c['semantic']:.3f} nv {c['novel_view_iou']:.3f} "
                + " ".join(f"{k} {_feature(c, k):.4g}" for k in FEATURES)
            )
    if args.finished:
        rows = {r["video"]: r for r in json.loads(Path(args.finished).read_text())["rows"]}
        pairs = [
            (t["novel_view_iou"], rows[v["video"]]["novel_view_iou"])
            for v, t in zip(videos, today)
            if v["video"] in rows and rows[v["video"]].get("template") == t["name"]
        ]
        a = np.asarray(pairs)
        print(
            f"\ntrial-end against finished novel view, same template ({len(a)} videos): "
            f"means {a[:, 0].mean():.3f} / {a[:, 1].mean():.3f}, correlation {np.corrcoef(a.T)[0, 1]:.3f}"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    a = add_log_parser(sub)
    a.add_argument("--own-template", action="store_true", help="each video's own asset, not retrieval's")
    a.add_argument("--candidates", type=int, help="retrieval's candidates tried (default: the preset's 3)")
    a.add_argument("--skip-logged", nargs="*", help="logs whose candidates are not tried again")
    a.add_argument(
        "--turned",
        action="store_true",
        help="each candidate also from the best view 90+ degrees of azimuth away",
    )
    a.add_argument(
        "--carried",
        action="store_true",
        help="each candidate also from the start carried by the camera's turn, where it is read (as the fit's trials)",
    )
    a.set_defaults(func=log)
    b = sub.add_parser("choose")
    b.add_argument("logs", nargs="+")
    b.add_argument("--finished")
    b.add_argument("--candidates", type=int, help="only each video's first N candidates, in the logs' order")
    b.add_argument(
        "--displacement",
        type=float,
        default=0.0,
        help="the base rule's displacement weight (1.5: the trials' rule since 2026-11-29; 0: the rule before)",
    )
    b.add_argument(
        "--spread",
        type=float,
        default=0.0,
        help="the base rule's weight on the body's turn in the world (0.016: the trials' rule since 2026-12-05)",
    )
    b.add_argument(
        "--best-start",
        action="store_true",
        help="of each candidate's logged starts, only the one the fit's trials keep (the shipped trial score)",
    )
    b.set_defaults(func=choose)
    args = ap.parse_args()
    args.func(args)


if __name__ == "__main__":
    main()
