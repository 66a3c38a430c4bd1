"""Mask quality of the `animalnet` segmenter against `grabcut`, its two weights chosen
leave-one-video-out; used by ``bench/video.py --part quality --segmenter animalnet --weights W``.

`animalnet` runs the `grabcut` tracker, then decides every frame again with the network's
evidence. The tracker's masks and the flow come from the same cache as ``--part quality``'s; the
network's evidence is computed once per video (cached by the frames, the flow, the weights' digest
and ``zooctl/video/animalnet.py``'s source), so every (net_weight, prior_weight) of the grid costs
only the decision. Also scored: the network alone (its connected part over even odds holding the
most probability, no tracker). Leave-one-out runs over every run at once, `grabcut` included.

Written into the output folder: ``animalnet.md`` (the table), ``animalnet.json``,
``overlays/animalnet-VIDEO.png`` (the masks' outline in green, the truth's in magenta) and
``curves/animalnet-VIDEO.png`` (J per frame of `grabcut`, the network alone and the default).
"""

from __future__ import annotations

import hashlib
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
# (net_weight, prior_weight, erase) tried; the first is the segmenter's default (chosen among
# these leave-one-video-out: BENCHMARKS.md)
GRID = (
    (1.0, 2.0, False),
    (2.0, 2.0, False),
    (4.0, 2.0, False),
    (1.0, 2.0, True),
    (1.0, 1.0, True),
    (0.5, 2.0, True),
)


def _digest(path: Path) -> str:
    return hashlib.blake2b(path.read_bytes(), digest_size=12).hexdigest()


def _label(nw: float, pw: float, erase: bool) -> str:
    return f"animalnet,net={nw:g},prior={pw:g}" + ("" if erase else ",adds")


def run(sequences, load, cache, base: dict, preset, flow_size, out: Path, weights: Path) -> dict:
    """`grabcut`, the network alone and `animalnet` at each of `GRID` on every video. ``load(seq)``
    -> (frames, truth); ``base``: the tracker's options. {video: {label: result}}."""
    import cv2
    from video_quality import _save, curve_plot, overlay_sheet, say, scored, segmenter_flow
    from video_quality import segment_video as grabcut_video

    from zooctl.video.animalnet import AnimalNetSegmenter
    from zooctl.video.flow import VideoFlow
    from zooctl.video.grabcut import resize_flows
    from zooctl.video.selftrain import main_animal

    seg = AnimalNetSegmenter(weights, **base)
    source = _digest(REPO / "zooctl" / "video" / "animalnet.py") + _digest(Path(weights))
    results: dict = {}
    for seq in sequences:
        frames, truth = load(seq)
        t, h, w = frames.shape[:3]
        tracked, g = grabcut_video(seq, frames, truth, cache, base, {}, preset, flow_size)
        flow, flow_key = segmenter_flow(cache, seg, frames, preset, flow_size)
        sw, sh = seg.flow_size(w, h)
        if tuple(flow.forward.shape[1:3]) != (sh, sw):
            flow = VideoFlow(
                *(resize_flows(f, sw, sh, frames) for f in (flow.forward, flow.backward)), None, None
            )
        path = cache.root / f"animalnet-{seq}-{flow_key}-{source}.npz" if cache.root else None
        if path is not None and path.is_file():
            with np.load(path) as z:
                ev, cpu = z["evidence"], float(z["cpu_s"])
        else:
            c0 = time.process_time()
            ev = np.asarray(seg.evidence(frames, flow))
            cpu = time.process_time() - c0
            if path is not None:
                _save(path, evidence=ev, cpu_s=np.float64(cpu))
        small = [
            cv2.resize(np.asarray(m, np.float32), (sw, sh), interpolation=cv2.INTER_AREA) > 0.5
            for m in tracked
        ]

        def full(masks, w=w, h=h):
            return np.stack(
                [
                    cv2.resize(m.astype(np.float32), (w, h), interpolation=cv2.INTER_LINEAR) > 0.5
                    for m in masks
                ]
            )

        res = {"grabcut": g}
        alone = full([main_animal(e) for e in ev])
        res["network alone"] = scored(alone, truth, {"evidence_cpu_s": cpu})
        masks_by = {}
        for nw, pw, erase in GRID:
            seg.net_weight, seg.prior_weight, seg.erase = nw, pw, erase
            masks = full([seg.decide(e, m) for e, m in zip(ev, small)])
            res[_label(nw, pw, erase)] = scored(masks, truth, {"evidence_cpu_s": cpu})
            masks_by[(nw, pw, erase)] = masks
        results[seq] = res
        d = _label(*GRID[0])
        say(
            f"  {seq:14s} grabcut {g['J']:.3f}, network alone {res['network alone']['J']:.3f}, "
            + ", ".join(
                f"{k.split(',', 1)[1]} {v['J']:.3f}" for k, v in res.items() if k.startswith("animalnet")
            )
            + f"; evidence {cpu:.1f} CPU s"
        )
        overlay_sheet(
            out / "overlays" / f"animalnet-{seq}.png", frames, masks_by[GRID[0]], truth, res[d]["per_frame"]
        )
        overlay_sheet(
            out / "overlays" / f"animalnet-alone-{seq}.png",
            frames,
            alone,
            truth,
            res["network alone"]["per_frame"],
        )
        curve_plot(
            out / "curves" / f"animalnet-{seq}.png",
            seq,
            {
                "default": res[d]["per_frame"],
                "grabcut": g["per_frame"],
                "network alone": res["network alone"]["per_frame"],
            },
            res[d],
        )
    return {"weights": str(weights), "grid": [list(p) for p in GRID], "videos": results}


def table(report: dict) -> tuple[str, dict]:
    """Markdown: per video `grabcut`, the network alone, each run in-sample, and the choice among
    all runs (`grabcut` included) leave-one-out."""
    from video_quality import DEVELOPED_ON, loo_numbers

    from zooctl.video.mask_quality import leave_one_out

    res = report["videos"]
    seqs = list(res)
    labels = list(res[seqs[0]])
    every = leave_one_out({lab: {s: res[s][lab]["J"] for s in seqs} for lab in labels}, prefer="grabcut")
    nets = leave_one_out(
        {lab: {s: res[s][lab]["J"] for s in seqs} for lab in labels if lab.startswith("animalnet")},
        prefer=_label(*GRID[0]),
    )
    head = ["video", "frames", *[f"`{lab}`" for lab in labels], "animalnet weights, leave-one-out (picked)"]
    head += ["any run or `grabcut`, leave-one-out (picked)"]
    rows = ["| " + " | ".join(head) + " |", "|---|" + "---:|" * (len(head) - 1)]
    for s in seqs:
        cells = [f"{s}{' *' if s in DEVELOPED_ON else ''}", str(res[s]["grabcut"]["frames"])]
        cells += [f"{res[s][lab]['J']:.3f}" for lab in labels]
        cells.append(f"{nets.held_out[s]:.3f} ({nets.picked[s].split(',', 1)[1]})")
        cells.append(f"{every.held_out[s]:.3f} ({every.picked[s]})")
        rows.append("| " + " | ".join(cells) + " |")
    mean = {lab: float(np.mean([res[s][lab]["J"] for s in seqs])) for lab in labels}
    cells = ["**mean**", str(sum(res[s]["grabcut"]["frames"] for s in seqs))]
    cells += [f"{mean[lab]:.3f}" for lab in labels]
    cells += [f"**{nets.held_out_mean:.3f}**", f"**{every.held_out_mean:.3f}**"]
    rows.append("| " + " | ".join(cells) + " |")
    numbers = loo_numbers({"animalnet": nets, "any": every})
    numbers["mean"] = mean
    note = (
        "\n\n`*`: the videos `grabcut`'s defaults were developed on. Leave-one-out: the run with the best "
        "mean J on the other six videos (ties keep the first), scored on the seventh; over the "
        "`animalnet` weights only, then over every run (`grabcut` and the network alone included).\n"
    )
    return "\n".join(rows) + note, numbers
