"""`zooctl view --bench DIR`: the benchmark table of `zooctl bench run DIR` (the store's fits of
DIR's videos, named ``bench-<video>-<ablation>``), each row opening its fit's page."""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

from zooctl.errors import UsageError

COLUMNS = ("mask_iou", "novel_view_iou", "miou", "mcham", "joint", "skinning", "reanimation")


def bench_fits(store: Path, folder: Path) -> list[dict[str, Any]]:
    """One row per finished fit of a benchmark video of ``folder`` in the store (every ablation)."""
    from zooctl.benchdata.run import ABLATIONS, bench_videos
    from zooctl.store.fits import FitStore

    vids = bench_videos(Path(folder))
    fits = FitStore(store)
    names = fits.names()
    rows = []
    for v in vids:
        prefix = f"bench-{v.name}-".lower()
        for n in names:
            ablation = n[len(prefix) :]
            if not n.startswith(prefix) or ablation not in ABLATIONS:
                continue
            rec = fits.get(n)
            if rec.get("status") != "done":
                continue
            m = rec.get("metrics", {})
            rows.append(
                {
                    "fit": n,
                    "video": v.name,
                    "ablation": ablation,
                    "template": rec.get("template"),
                    "frames": rec.get("frames"),
                    "wall_s": (rec.get("timings") or {}).get("total_wall"),
                    **{k: m.get(k) for k in COLUMNS},
                }
            )
    if not rows:
        raise UsageError(
            f"the store holds no finished fits of the benchmark videos in {folder}",
            hint=f"run `zooctl bench run {folder}` first (with the same --store)",
        )
    return rows


def write_bench_site(store: Path, folder: Path, rows: list[dict[str, Any]], out: Path, bar: Any) -> Path:
    """The table in ``out/index.html`` and every row's fit page in ``out/fits/<fit>/``.
    ``bar(description)`` gives a ``progress(done, total)`` callback."""
    from .fit_data import load_fit_view
    from .site import start_site, write_data, write_fit_site, write_index

    start_site(out, "bench", {"kind": "bench", "fits": len(rows)})
    done = bar("fit pages")
    for i, row in enumerate(rows):
        view = load_fit_view(store, row["fit"])
        write_fit_site(view, out / "fits" / row["fit"], up="../../", back="../../index.html")
        row["page"] = f"fits/{row['fit']}/index.html"
        done(i + 1, len(rows))
    keep = {r["fit"] for r in rows}
    if (out / "fits").is_dir():  # an earlier export's fits that are gone from the store
        for p in (out / "fits").iterdir():
            if p.is_dir() and p.name not in keep:
                shutil.rmtree(p)
    write_data(
        out, {"kind": "bench", "folder": str(Path(folder).resolve()), "columns": COLUMNS, "rows": rows}
    )
    return write_index(out, "bench")
