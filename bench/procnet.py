"""Evaluate `procnet` weights on frozen features (issue 21): leave-one-out over the 28 shared assets
(alone, with the starter bank) and the procedural held-out set, without re-rendering per model.

The renders are those of `bench/retrieval.py` (each asset's 24 bank views with the seed `bank add`
uses, query video i with seed 1000 + i, 8 frames), reduced once to the frozen effnet and silhouette
features the head reads and cached in ``--features``. Scoring is `nearest` + `zsum`, as a search.
The held-out set is 60 random animals of seed 1 (6 per body plan; training uses seed 0): the query
is 4 views of one animal, the bank the other animals' 12 views.

    .venv/bin/python bench/procnet.py --weights STORE/models/procnet.npz [--weights other.npz]
        [--features bench/out/procnet_features.npz] [--out bench/out/procnet.json]

`--adapt TRAINING.npz` (a training set cached by `zooctl embed train` in STORE/cache/procnet/)
evaluates `embed train --bank` strictly leave-one-out: for each shared query a head fine-tuned
from the first --weights on that set plus the other 27 assets' views (with their body plans as
tags, or identity only with --untagged), then the query searched among those 27.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from _util import SHARED, machine

from zooctl.retrieval.procnet_eval import (
    HELD_OUT_ANIMALS,
    evaluate_weights,
    load_features,
    loo_adapted,
    render_features,
    save_features,
)


def print_rows(rows: list[dict]) -> None:
    for row in rows:
        print(
            f"  {row['set']:<15} {row['embedders']:<28} top-1 {row['top1']:>2}/{row['queries']}"
            f" (answerable {row['top1_answerable']}/{row['answerable']}), top-3 {row['top3']}/{row['queries']}"
            + (f"  misses: {', '.join(row['misses'])}" if row.get("misses") else "")
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--weights", action="append", default=[], type=Path)
    ap.add_argument("--features", type=Path, default=Path("bench/out/procnet_features.npz"))
    ap.add_argument("--out", type=Path, default=Path("bench/out/procnet.json"))
    ap.add_argument("--adapt", type=Path, default=None, help="training-set .npz: evaluate --bank adaptation")
    ap.add_argument("--untagged", action="store_true", help="with --adapt: bank views without plan labels")
    ap.add_argument("--adapt-steps", type=int, default=300)
    ap.add_argument("--adapt-lr", type=float, default=3e-4)
    ap.add_argument("--adapt-fraction", type=float, default=0.25, help="share of bank assets per batch")
    args = ap.parse_args()
    if args.features.exists():
        feats = load_features(args.features)
    else:
        files = sorted((SHARED / "assets").rglob("*.glb"))
        if not files:
            sys.exit(f"bench/procnet.py needs the shared assets at {SHARED / 'assets'}")
        feats = render_features(
            files, HELD_OUT_ANIMALS, progress=lambda m: print(f"  {m}", file=sys.stderr, flush=True)
        )
        save_features(args.features, feats)
    report = {"machine": machine(), "command": " ".join(sys.argv), "models": {}}
    for w in args.weights or [None]:
        r = evaluate_weights(feats, w)
        report["models"][str(w)] = r
        print(f"== {w or 'effnet + silhouette only'}")
        print_rows(r["rows"])
    if args.adapt is not None:
        from zooctl.embed.procnet import load_head
        from zooctl.retrieval.train_data import read_cached
        from zooctl.retrieval.train_embedder import TrainConfig

        w, info = load_head(args.weights[0])
        cfg = TrainConfig(steps=args.adapt_steps, lr=args.adapt_lr, bank_fraction=args.adapt_fraction)
        r = loo_adapted(feats, read_cached(args.adapt), w, cfg, tagged=not args.untagged)
        report["adapted"] = r
        print(
            f"== {args.weights[0]} adapted to the bank, leave-one-out ({'untagged' if args.untagged else 'tagged'}, {args.adapt_steps} steps)"
        )
        print_rows(r["rows"])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(report, indent=1, default=lambda o: np.asarray(o).tolist()))
    print(f"machine: {report['machine']}\nwrote {args.out}")


if __name__ == "__main__":
    main()
