"""Retrieval benchmark (issue 6): leave-one-out accuracy over the 28 shared assets and over the
procedural starter bank, `bank add` cost per asset with views and embeddings, and search latency
with a bank of 10,000 synthetic assets (scoring in-process, and the whole `zooctl bank search`).

The semantic term (issue 49): the seven shared real videos searched in a bank of the 28 shared
assets and the starter animals, labelled as a user's would be (name, tags, views), by body plan
and family at top-1 and top-3; the semantic weight swept, and chosen in-sample and leave-one-out
over the real videos and the rendered leave-one-out queries together. ``--real-store DIR`` reuses
a store that holds the seven videos (``video add`` without a box) and that bank; without it one is
built in a temporary folder (about 15 minutes on 2 cores). ``--heldout``: the shared assets also
queried with renders in styles the bank's views never use (`zooctl.retrieval.styles`), leave one
asset out, at every weight, with how many of appearance's right answers the term loses.
``--fit-choice``: the template `zooctl fit` picks for each real video (retrieval and the template
trials, no full fit).

    .venv/bin/python bench/retrieval.py [--embedder effnet --embedder silhouette] [--views 24]
        [--synthetic 10000] [--skip-loo] [--skip-real] [--real-store DIR] [--heldout]
        [--fit-choice] [--out bench/out/retrieval.json]
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _util import SHARED, machine, time_command, write_json

from zooctl.cli._common import print_table
from zooctl.retrieval.benchmark import COLUMNS, loo_benchmark, search_latency, summary_rows, synthetic_bank
from zooctl.retrieval.semantic import SEMANTIC_WEIGHT
from zooctl.retrieval.semantic_bench import asset_truth, choose_loo, judge
from zooctl.retrieval.styles import HELDOUT_STYLES

REAL_VIDEOS = ("dog", "cows", "blackswan", "bear", "elephant", "dog-agility", "mallard-water")
WEIGHTS = (0.0, 1.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 16.0)


def time_once(args: list[str], env: dict) -> float:
    """Wall seconds of one `zooctl ...` run in a new process."""
    exe = Path(sys.executable).with_name("zooctl")
    t = time.perf_counter()
    subprocess.run([str(exe), *args], check=True, capture_output=True, env=dict(os.environ, **env))
    return time.perf_counter() - t


def build_real_store(root: Path) -> None:
    """The seven shared videos (`video add` as a user runs it: no box, the default flow, which the
    masks' motion model uses) and a bank of the 28 shared assets and the starter animals (`bank
    seed`, `bank add`)."""
    env = {"ZOOCTL_STORE": str(root)}
    for v in REAL_VIDEOS:
        time_once(["video", "add", str(SHARED / "videos" / v / "JPEGImages"), "--name", v, "-q"], env)
    time_once(["bank", "seed"], env)
    time_once(["bank", "add", *map(str, sorted((SHARED / "assets").rglob("*.glb")))], env)


def real_benchmark(store: Path, embedders: list[str], frames: int) -> dict:
    """Each real video searched at every weight of `WEIGHTS`: top 3 and the judgement."""
    from zooctl.retrieval.search import search_source
    from zooctl.store.bank import Bank

    videos = json.loads((SHARED / "videos" / "labels.json").read_text())
    asset_labels = json.loads((SHARED / "assets" / "labels.json").read_text())
    bank = Bank.open(store)
    entries = bank.list()
    truths = {
        e["name"]: asset_truth(e["name"], bank.card(e["name"]).get("meta", {}), asset_labels) for e in entries
    }
    out = {"labels": {e["name"]: [e.get("label"), e.get("label_source")] for e in entries}, "weights": {}}
    for w in WEIGHTS:
        rows = {}
        for v in REAL_VIDEOS:
            _, res = search_source(
                bank, v, embedders, top=3, frames=frames, store_root=store, semantic_weight=w
            )
            rows[v] = judge(videos[v], [m.name for m in res.matches], truths)
            rows[v]["classes"] = res.classes
        out["weights"][str(w)] = rows
    return out


def fit_choice(store: Path, preset_name: str = "fast", candidates: int | None = None) -> dict:
    """The template `zooctl fit` chooses for each real video: retrieval (`retrieve`: the semantic
    term and the best asset of the family among the trials) then the template trials
    (`select_template`), stopped there (no full fit); judged as `real_benchmark` judges."""
    from zooctl.fit.config import preset
    from zooctl.fit.job import load_source
    from zooctl.fit.template import pick_trial, select_template, trial_score
    from zooctl.store.bank import Bank

    videos = json.loads((SHARED / "videos" / "labels.json").read_text())
    asset_labels = json.loads((SHARED / "assets" / "labels.json").read_text())
    bank = Bank.open(store)
    truths = {
        e["name"]: asset_truth(e["name"], bank.card(e["name"]).get("meta", {}), asset_labels)
        for e in bank.list()
    }
    rows = {}
    for v in REAL_VIDEOS:
        cfg = preset(preset_name)
        cfg.trials.candidates = candidates or cfg.trials.candidates
        t, c = time.perf_counter(), time.process_time()
        video = load_source(v, store, None, cfg.max_frames)
        asset, cands, _, t_trials = select_template(bank, None, video, cfg)
        chosen = judge(videos[v], [asset.name], truths)
        first = judge(videos[v], [x["name"] for x in cands], truths)
        tried = cands[: cfg.trials.candidates]
        # the pick without the displacement term (the rule before it), from the same trials
        before = tried[pick_trial([trial_score(x["trial_iou"], x.get("semantic") or 0.0) for x in tried])][
            "name"
        ]
        was = judge(videos[v], [before], truths)
        rows[v] = {
            "chosen": asset.name,
            "candidates": [
                [x["name"], x.get("trial_iou"), x.get("semantic"), x.get("trial_displacement")] for x in tried
            ],
            "rank": chosen["rank"],
            "plan": chosen["plan1"],
            "family": chosen["family1"],
            "chosen_without_displacement": before,
            "plan_without_displacement": was["plan1"],
            "family_without_displacement": was["family1"],
            "retrieval_plan1": first["plan1"],
            "retrieval_family1": first["family1"],
            "trials_s": t_trials,
            "wall_s": time.perf_counter() - t,
            "cpu_s": time.process_time() - c,
        }
        r = rows[v]
        print(
            f"  {v}: {asset.name} (trials {', '.join(f'{n} {i} sem {s} disp {d}' for n, i, s, d in r['candidates'])}; "
            f"without the displacement term {before}) "
            f"plan {int(r['plan'])} family {int(r['family'])} at {r['rank']}; {r['wall_s']:.0f} s wall, "
            f"{r['cpu_s']:.0f} s CPU",
            file=sys.stderr,
            flush=True,
        )
    return rows


def heldout_report(report: dict) -> None:
    """Held-out render styles (leave-one-asset-out, renders drawn as the bank's views never are): at
    each weight, top-1 body plan of the answerable queries per style and in all, and how many of
    the queries appearance alone (weight 0) gets right the semantic term loses."""
    held = report.get("shared", {}).get("heldout", {})
    if not held:
        return
    styles = list(held)
    rows = []
    for w in WEIGHTS:
        if str(w) not in held[styles[0]]:
            continue
        cells, right, total, lost = [], 0, 0, 0
        for st in styles:
            base = {x["query"]: x for x in held[st]["0.0"]["rows"] if x["answerable"]}
            now = {x["query"]: x for x in held[st][str(w)]["rows"] if x["answerable"]}
            r = sum(x["top1_plan"] for x in now.values())
            cells.append(f"{r}/{len(now)}")
            right, total = right + r, total + len(now)
            lost += sum(base[q]["top1_plan"] and not now[q]["top1_plan"] for q in now)
        rows.append([f"{w:g}", *cells, f"{right}/{total}", str(lost)])
    report["heldout_summary"] = rows
    print_table(
        [("weight", "right"), *[(st, "right") for st in styles], ("all", "right"), ("lost vs 0", "right")],
        rows,
        title="held-out render styles, leave-one-asset-out: top-1 body plan (answerable queries)",
    )


def semantic_report(report: dict) -> None:
    """Tables: every weight on both query sets; the weight chosen in-sample and leave-one-out."""
    real = report.get("real", {}).get("weights", {})
    syn = report.get("shared", {}).get("semantic", {})
    points: dict[float, dict[str, float]] = {}
    rows = []
    for w in WEIGHTS:
        r, s = real.get(str(w), {}), syn.get(str(w))
        pts = {f"real:{v}": x["family1"] + x["plan1"] for v, x in r.items()}
        if s is not None:
            pts.update({f"syn:{x['query']}": float(x["top1_plan"]) for x in s["rows"] if x["answerable"]})
        points[w] = pts
        syn_ans = sum(x["top1_plan"] for x in s["rows"] if x["answerable"]) if s else None
        n_ans = sum(x["answerable"] for x in s["rows"]) if s else None
        rows.append(
            [f"{w:g}"]
            + [f"{sum(x[k] for x in r.values())}/{len(r)}" for k in ("family1", "family3", "plan1", "plan3")]
            + (
                [f"{syn_ans}/{n_ans}", f"{sum(x['top3_plan'] for x in s['rows'])}/{len(s['rows'])}"]
                if s
                else ["-", "-"]
            )
        )
    cols = [("weight", "right"), ("real family top-1", "right"), ("real family top-3", "right")]
    cols += [("real plan top-1", "right"), ("real plan top-3", "right")]
    cols += [("rendered LOO top-1 answerable", "right"), ("rendered LOO top-3", "right")]
    print_table(
        cols,
        rows,
        title="semantic weight: real videos (family at the rank the bank reaches) and rendered leave-one-out",
    )
    queries = sorted(points[WEIGHTS[0]])
    w_in, ins, loo = choose_loo(points, queries)
    report["semantic_choice"] = {
        "in_sample_weight": w_in,
        "in_sample": ins,
        "loo": loo,
        "default": SEMANTIC_WEIGHT,
    }
    for part in ("real", "syn"):
        keys = [q for q in queries if q.startswith(part + ":")]
        print(
            f"{part}: in-sample (weight {w_in:g}) {sum(ins[q] for q in keys):g}, leave-one-out "
            f"{sum(loo[q] for q in keys):g} of {(2 if part == 'real' else 1) * len(keys)}"
        )
    heldout_report(report)
    chosen = real.get(str(SEMANTIC_WEIGHT), {})
    print_table(
        [
            ("video", "left"),
            ("top 3", "left"),
            ("family at", "left"),
            ("family 1/3", "left"),
            ("plan 1/3", "left"),
            ("classes seen", "left"),
        ],
        [
            [
                v,
                ", ".join(x["top"]),
                x["rank"] or "-",
                f"{int(x['family1'])}/{int(x['family3'])}",
                f"{int(x['plan1'])}/{int(x['plan3'])}",
                ", ".join(f"{c} {p:.2f}" for c, p in x["classes"][:2]),
            ]
            for v, x in chosen.items()
        ],
        title=f"real videos at the default weight {SEMANTIC_WEIGHT:g}",
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--embedder", action="append", default=None)
    ap.add_argument("--views", type=int, default=24)
    ap.add_argument("--frames", type=int, default=8)
    ap.add_argument(
        "--synthetic", type=int, default=10000, help="assets in the synthetic latency bank (0: skip)"
    )
    ap.add_argument("--skip-loo", action="store_true")
    ap.add_argument(
        "--shared-only", action="store_true", help="leave-one-out over the shared assets' bank only"
    )
    ap.add_argument("--skip-real", action="store_true", help="no real-video retrieval (issue 49)")
    ap.add_argument("--real-store", type=Path, default=None, help="a store with the 7 videos and the bank")
    ap.add_argument(
        "--heldout",
        action="store_true",
        help="also query the shared assets with renders in the held-out styles (zooctl.retrieval.styles)",
    )
    ap.add_argument(
        "--fit-choice", action="store_true", help="also the template `zooctl fit` chooses for each real video"
    )
    ap.add_argument(
        "--trial-candidates", type=int, help="--fit-choice: candidates the trials try (default 3)"
    )
    ap.add_argument("--out", type=Path, default=Path("bench/out/retrieval.json"))
    args = ap.parse_args()
    embedders = args.embedder or ["effnet", "silhouette"]
    report = {"machine": machine(), "command": " ".join(sys.argv)}
    tmp = Path(tempfile.mkdtemp(prefix="zooctl-bench-retrieval-"))
    try:
        if not args.skip_loo:
            from zooctl.io.gltf_import import load_gltf
            from zooctl.procedural import starter_assets

            files = sorted((SHARED / "assets").rglob("*.glb"))
            if not files:
                sys.exit(f"bench/retrieval.py needs the shared assets at {SHARED / 'assets'}")
            shared = [load_gltf(f, f.stem) for f in files]
            starter = starter_assets()
            # shared+starter: the shared assets queried against a bank that also holds the starter
            # animals, as a real user's bank (`make demo`) does
            runs = (
                ("shared", shared, None),
                ("shared+starter", shared + starter, [a.name for a in shared]),
                ("starter", starter, None),
            )
            for label, assets, queries in runs[:1] if args.shared_only else runs:
                r = loo_benchmark(
                    assets,
                    tmp / label,
                    embedders,
                    n_views=args.views,
                    frames=args.frames,
                    progress=lambda msg, i, n: print(f"  [{i}/{n}] {msg}", file=sys.stderr, flush=True),
                    queries=queries,
                    semantic_weights=list(WEIGHTS) if label == "shared" else None,
                    styles=list(HELDOUT_STYLES) if args.heldout and label == "shared" else None,
                )
                report[label] = r
                print_table(
                    COLUMNS,
                    summary_rows(r),
                    title=f"leave-one-out: {r['queries']} queries, bank of {r['assets']} {label} assets ({args.views} views, {args.frames} query frames)",
                )
                print(
                    f"views + embeddings per asset: median {r['index_seconds_per_asset_median']:.2f} s, max {r['index_seconds_per_asset_max']:.2f} s"
                )
        if not args.skip_real:
            store = args.real_store
            if store is None:
                store = tmp / "real"
                build_real_store(store)
            report["real"] = real_benchmark(store, embedders, args.frames)
            report["real"]["store"] = str(store)
            t = time_command(["bank", "search", "dog"], env={"ZOOCTL_STORE": str(store)}, repeat=5)
            report["real"]["search_dog_median_s"] = t
            print(
                f"whole `zooctl bank search dog` (stored, cached), {len(report['real']['labels'])} assets: {t:.2f} s (median of 5)"
            )
            semantic_report(report)
            if args.fit_choice:
                report["fit_choice"] = fit_choice(store, candidates=args.trial_candidates)
                ok = report["fit_choice"].values()
                print(
                    f"zooctl fit's template (retrieval + trials): plan {sum(r['plan'] for r in ok)}/{len(ok)}, "
                    f"family {sum(r['family'] for r in ok)}/{len(ok)}; without the displacement term: plan "
                    f"{sum(r['plan_without_displacement'] for r in ok)}/{len(ok)}, "
                    f"family {sum(r['family_without_displacement'] for r in ok)}/{len(ok)}"
                )
        if args.synthetic:
            dims = {"effnet": 1280, "silhouette": 576}
            root = tmp / "synthetic"
            synthetic_bank(root, args.synthetic, dims, n_views=args.views)
            scoring = search_latency(root, dims, frames=args.frames)
            dog = SHARED / "videos" / "dog"
            env = {"ZOOCTL_STORE": str(root)}
            whole = first = repeat = None
            if dog.is_dir():
                whole = time_command(["bank", "search", str(dog)], env=env, repeat=3)
                # a stored video: the first search embeds and caches the query, repeats read the cache
                time_once(["video", "add", str(dog), "--name", "dog", "-q"], env)
                from zooctl.store.videos import VideoStore

                cache = VideoStore(root).cache_dir("dog")
                firsts = []
                for _ in range(3):
                    shutil.rmtree(cache, ignore_errors=True)
                    firsts.append(time_once(["bank", "search", "dog"], env))
                first = statistics.median(firsts)
                repeat = time_command(["bank", "search", "dog"], env=env, repeat=7)
            report["search"] = {
                "assets": args.synthetic,
                "views": args.views,
                "scoring_median_s": scoring["scoring_s"],
                "load_median_s": scoring["load_s"],
                "command_folder_median_s": whole,
                "command_stored_first_median_s": first,
                "command_stored_repeat_median_s": repeat,
            }
            print(
                f"search among {args.synthetic} assets: scoring {1000 * scoring['scoring_s']:.0f} ms, index + pack check {1000 * scoring['load_s']:.0f} ms (medians)"
                + (
                    f"; whole `zooctl bank search`: DAVIS folder {whole:.2f} s, stored video first"
                    f" {first:.2f} s, repeat {repeat:.2f} s (medians)"
                    if whole
                    else ""
                )
            )
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    write_json(args.out, report, indent=1)
    print(f"machine: {report['machine']}\nwrote {args.out}")


if __name__ == "__main__":
    main()
