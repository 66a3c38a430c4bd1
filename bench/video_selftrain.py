"""Mask quality of the `selftrain` segmenter against `grabcut`, every setting chosen
leave-one-video-out; used by ``bench/video.py --part quality --segmenter selftrain``.

`selftrain` runs the `grabcut` tracker first and learns from its masks. The tracker's masks come
from the same cache as ``--part quality``'s (keyed by the frames, the flow, the tracker's options
and its modules' source), so each extra setting costs only the learning; the learned masks are
cached too, keyed also by ``zooctl/video/selftrain.py``'s source. A setting of the grid is one
value of one option, the rest at the defaults. Leave-one-out is also run over every run at once,
`grabcut` among them: which segmenter is the default is itself a choice made on six videos and
scored on the seventh.

Written into the output folder: ``selftrain.md`` (the table), ``selftrain.json``,
``overlays/selftrain-VIDEO.png`` (the learned masks' outline in green, the truth's in magenta)
and ``curves/selftrain-VIDEO.png`` (J per frame of `grabcut` and of each `selftrain` run).
"""

from __future__ import annotations

import hashlib
import time
from functools import partial
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
# the settings of `selftrain` that were chosen by looking at the shared videos, with the values tried
GRID: dict[str, tuple] = {
    "deep_weight": (0.0, 0.5, 1.0),
    "prior_weight": (1.0, 2.0, 3.0),
    "band": (0.03, 0.1, 0.2),
}


def _source() -> str:
    return hashlib.blake2b(
        (REPO / "zooctl" / "video" / "selftrain.py").read_bytes(), digest_size=12
    ).hexdigest()


def segment_video(seq, frames, truth, cache, base: dict, options: dict, preset, flow_size):
    """`selftrain` with ``options`` on one video (its tracker's masks from ``cache``); (masks, result)."""
    from video_quality import scored, segmenter_flow
    from video_quality import segment_video as grabcut_video

    from zooctl.plugins import get_registry

    seg = get_registry().get("segmenter", "selftrain").create(**base, **options)
    flow, flow_key = segmenter_flow(cache, seg, frames, preset, flow_size)
    tracked, info = grabcut_video(seq, frames, truth, cache, base, {}, preset, flow_size)

    def cached_tracker(*args, **kw):
        seg.tracker.report = {k: info.get(k) for k in ("seed_frame",)}
        return tracked

    seg.tracker.segment = cached_tracker

    def run():
        t0, c0 = time.perf_counter(), time.process_time()
        masks = seg.segment(frames, flow=flow)
        return np.asarray(masks, bool), {
            "learn_s": time.perf_counter() - t0,
            "learn_cpu_s": time.process_time() - c0,
            **seg.report.get("self_training", {}),
        }

    key_opts = {"segmenter": "selftrain", "source": _source(), **base, **options}
    masks, learn = cache.masks(frames, flow_key, key_opts, None, run)
    return masks, scored(masks, truth, learn)


def run(sequences, load, cache, base: dict, preset, flow_size, out: Path, grid: dict | None = None) -> dict:
    """`grabcut` and `selftrain` (defaults and each grid value) on every video; overlays and curves.
    ``load(seq)`` -> (frames, truth). {video: {label: result}} with labels "grabcut", "selftrain",
    "selftrain,K=V"."""
    from video_quality import _label, configs, curve_plot, run_settings
    from video_quality import segment_video as grabcut_video

    from zooctl.plugins import get_registry

    grid = GRID if grid is None else grid
    seg = get_registry().get("segmenter", "selftrain").create()
    defaults = {k: getattr(seg, k) for k in grid}
    runs = configs(grid, defaults)
    segment = partial(segment_video, cache=cache, base=base, preset=preset, flow_size=flow_size)
    results: dict = {}
    for seq in sequences:
        frames, truth = load(seq)
        _, g = grabcut_video(seq, frames, truth, cache, base, {}, preset, flow_size)
        results[seq] = {"grabcut": g}
        results[seq] |= run_settings(
            seq,
            frames,
            truth,
            runs,
            segment,
            lambda o: "selftrain" + ("," + _label(o) if o else ""),
            partial(_progress_line, g),
            out / "overlays" / f"selftrain-{seq}.png",
        )
        curves = {k: v["per_frame"] for k, v in results[seq].items() if k in ("grabcut", "selftrain")}
        curve_plot(
            out / "curves" / f"selftrain-{seq}.png",
            seq,
            {"default": curves["selftrain"], "grabcut": curves["grabcut"]},
            results[seq]["selftrain"],
        )
    return {"defaults": defaults, "grid": {k: list(v) for k, v in grid.items()}, "videos": results}


def _progress_line(grabcut: dict, seq: str, label: str, r: dict) -> str:
    return (
        f"  {seq:14s} {label:30s} J={r['J']:.3f} (min {r['J_min']:.3f}; grabcut {grabcut['J']:.3f}), "
        f"learning {r['learn_cpu_s']:.1f} CPU s, {r.get('animal_cells')} animal / "
        f"{r.get('background_cells')} background cells, {r.get('changed')} of the mask changed"
    )


def table(report: dict) -> tuple[str, dict]:
    """Markdown: per video `grabcut`, `selftrain` at its defaults, each grid setting in-sample and
    leave-one-out, and the choice among all runs (`grabcut` included) leave-one-out."""
    from video_quality import DEVELOPED_ON, loo_numbers

    from zooctl.video.mask_quality import leave_one_out

    res, grid, defaults = report["videos"], report["grid"], report["defaults"]
    seqs = list(res)

    def label(k, v):
        return "selftrain" if v == defaults[k] else f"selftrain,{k}={v}"

    loo = {
        k: leave_one_out({v: {s: res[s][label(k, v)]["J"] for s in seqs} for v in vals}, prefer=defaults[k])
        for k, vals in grid.items()
    }
    every = leave_one_out(
        {lab: {s: res[s][lab]["J"] for s in seqs} for lab in res[seqs[0]]}, prefer="grabcut"
    )
    head = ["video", "frames", "`grabcut` J", "**`selftrain`** J (worst frame)"]
    for k in grid:
        head += [f"`{k}` best on all ({loo[k].best}), in-sample", f"`{k}` leave-one-out (picked)"]
    head += ["any run or `grabcut`, leave-one-out (picked)"]
    rows = ["| " + " | ".join(head) + " |", "|---|" + "---:|" * (len(head) - 1)]
    for s in seqs:
        st = res[s]["selftrain"]
        cells = [
            f"{s}{' *' if s in DEVELOPED_ON else ''}",
            str(st["frames"]),
            f"{res[s]['grabcut']['J']:.3f}",
        ]
        cells.append(f"{st['J']:.3f} ({st['J_min']:.3f})")
        for k in grid:
            cells += [f"{loo[k].in_sample[s]:.3f}", f"{loo[k].held_out[s]:.3f} ({loo[k].picked[s]})"]
        cells.append(f"{every.held_out[s]:.3f} ({every.picked[s]})")
        rows.append("| " + " | ".join(cells) + " |")
    mean = {lab: float(np.mean([res[s][lab]["J"] for s in seqs])) for lab in ("grabcut", "selftrain")}
    cells = ["**mean**", str(sum(res[s]["grabcut"]["frames"] for s in seqs)), f"{mean['grabcut']:.3f}"]
    cells.append(f"**{mean['selftrain']:.3f}**")
    for k in grid:
        cells += [f"{loo[k].in_sample_mean:.3f}", f"**{loo[k].held_out_mean:.3f}**"]
    cells.append(f"**{every.held_out_mean:.3f}**")
    rows.append("| " + " | ".join(cells) + " |")
    numbers = loo_numbers({**loo, "any": every})
    numbers["mean"] = mean
    note = (
        "\n\n`*`: the videos `grabcut`'s defaults were developed on. Each `selftrain` setting is varied "
        "alone (the rest at the defaults); leave-one-out: the value with the best mean J on the other six "
        "videos (ties keep the default), scored on the seventh. Last column: the same over every run "
        "(`grabcut` and each `selftrain` setting) at once.\n"
    )
    return "\n".join(rows) + note, numbers
