"""How much of their surface characters tear (`zooctl.fit.outputs.surface_tear`), for fits already
stored and for the artists' own clips of a bank: the figures of BENCHMARKS.md, "A torn surface".

    python bench/tear.py fits STORE [--suffix=-full ...] [--out tears.json]
    python bench/tear.py clips STORE

``fits`` reads every stored fit's character (its ``fit`` clip) and prints the mean and median
share torn, per name suffix when given (``bench run`` names its fits ``bench-VIDEO-ABLATION``), so
fits made before the metric entered the record can be scored. Seams are found on the fit's
template, from the store's bank (as the fit does; on the character's own rest shape, with a note,
where the bank no longer holds it). ``clips`` scores every clip of
every bank asset: what articulation by an artist tears.
"""

from __future__ import annotations

import argparse
import json
import statistics
from pathlib import Path


def seam_positions(character, template):
    """(V, 3) each of the character's vertices at its template vertex's position, through the
    faces (the colour bake's atlas splits vertices but keeps the faces and their order), or None
    when the two do not share their faces."""
    import numpy as np

    if template is None or template.faces.shape != character.faces.shape:
        return None
    at = np.zeros_like(np.asarray(character.vertices, np.float64))
    at[character.faces.reshape(-1)] = np.asarray(template.vertices, np.float64)[template.faces.reshape(-1)]
    return at


def fits(args) -> None:
    from zooctl.errors import NotFoundError
    from zooctl.fit.outputs import surface_tear
    from zooctl.store.bank import Bank
    from zooctl.store.fits import FitStore

    store, bank = FitStore(Path(args.store)), Bank(Path(args.store))
    tears, templates = {}, {}
    for name in sorted(store.names()):
        try:
            character = store.character(name)
        except NotFoundError:  # a fit that did not finish (or is running) has no character yet
            print(f"{name}: no character, skipped")
            continue
        template = store.get(name).get("template")
        if template not in templates:
            try:
                templates[template] = bank.get(template)
            except NotFoundError:
                templates[template] = None
                print(f"template {template} not in the bank: its fits' seams found on their own rest shape")
        tears[name] = surface_tear(character, seams=seam_positions(character, templates[template]))
    if args.out:
        Path(args.out).write_text(json.dumps(tears, indent=1))
    for suffix in args.suffix or [""]:
        values = [v for k, v in tears.items() if k.endswith(suffix)]
        if values:
            print(
                f"{suffix or 'all'}: {len(values)} fits, torn mean {100 * statistics.mean(values):.2f} %, "
                f"median {100 * statistics.median(values):.2f} %"
            )


def clips(args) -> None:
    from zooctl.fit.outputs import surface_tear
    from zooctl.store.bank import Bank

    bank = Bank(Path(args.store))
    values = []
    for name in sorted(bank.names()):
        asset = bank.get(name)
        values += [surface_tear(asset, clip) for clip in asset.clips]
    if not values:
        print("no clips in the bank")
        return
    values.sort()
    print(
        f"{len(values)} clips: torn mean {100 * statistics.mean(values):.2f} %, 90th percentile "
        f"{100 * values[int(0.9 * (len(values) - 1))]:.2f} %, most {100 * values[-1]:.2f} %"
    )


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    f = sub.add_parser("fits")
    f.add_argument("store")
    f.add_argument("--suffix", action="append", default=[])
    f.add_argument("--out", default=None)
    c = sub.add_parser("clips")
    c.add_argument("store")
    a = ap.parse_args()
    {"fits": fits, "clips": clips}[a.cmd](a)
