"""Mask quality of the `animalnet` segmenter against `grabcut`, its settings chosen
leave-one-video-out; used by ``bench/video.py --part quality --segmenter animalnet --weights W``.

`animalnet` runs the `grabcut` tracker, looks at every third frame with the network, replaces the
tracker's masks with the network's animal when that moves against the camera more than the tracked
mask does (``switch_motion``), and relabels the video with `selftrain`'s per-video classifier
(``relabel``). The tracker's masks and the flow come from the same cache as ``--part quality``'s;
every setting of `GRID` runs `AnimalNetSegmenter.decide_near` on them (a few CPU seconds a video).
Also scored: the network alone on every frame (its connected part over even odds holding the most
probability, no tracker; its evidence cached by the frames, the flow, the weights' digest and
``zooctl/video/animalnet.py``'s source). Leave-one-out runs over the `animalnet` settings (ties keep
the default, `GRID`'s first), then over every run with `grabcut` (ties keep `grabcut`).

Written into the output folder: ``animalnet.md`` (the table), ``animalnet.json``,
``overlays/animalnet-VIDEO.png`` (the default's masks' outline in green, the truth's in magenta),
``overlays/animalnet-alone-VIDEO.png`` (the network alone) and ``curves/animalnet-VIDEO.png`` (J per
frame of `grabcut`, the network alone and the default).
"""

from __future__ import annotations

import hashlib
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
# (switch_motion, relabel, net_weight, relabel options) tried; the first is the segmenter's default.
# -1: never switch. The relabelling's weights (`selftrain`'s, chosen on these videos) are varied too.
# Every setting tried on these videos is here, so that leave-one-out chooses among all of them.
EARLIER = (  # before the motion model (motion_weight 0)
    (0.5, True, 0.0, ()),
    (0.25, True, 0.0, ()),
    (1.0, True, 0.0, ()),
    (-1.0, True, 0.0, ()),
    (0.5, True, 0.0, (("deep_weight", 0.0),)),
    (0.5, True, 0.0, (("deep_weight", 1.0),)),
    (0.5, True, 0.0, (("prior_weight", 2.0),)),
    (0.5, True, 0.0, (("prior_weight", 3.0),)),
    (0.5, True, 0.0, (("band", 0.03),)),
    (0.5, True, 0.0, (("band", 0.2),)),
    # the first grid, around the relabelling's `selftrain` defaults (prior_weight 2)
    (0.25, True, 0.0, (("prior_weight", 2.0),)),
    (1.0, True, 0.0, (("prior_weight", 2.0),)),
    (-1.0, True, 0.0, (("prior_weight", 2.0),)),
    (0.5, True, 0.0, (("prior_weight", 2.0), ("deep_weight", 0.0))),
    (0.5, True, 0.0, (("prior_weight", 2.0), ("deep_weight", 1.0))),
    (0.5, True, 0.0, (("prior_weight", 2.0), ("band", 0.03))),
    (0.5, True, 0.0, (("prior_weight", 2.0), ("band", 0.2))),
)
GRID = (
    (0.5, True, 0.0, ()),
    (0.5, True, 0.0, (("motion_weight", 0.25),)),
    (0.5, True, 0.0, (("motion_weight", 0.5),)),
    (0.5, True, 0.0, (("motion_weight", 1.0),)),
    (0.5, True, 0.0, (("motion_clip", 1.5),)),
    *((s, r, n, (("motion_weight", 0.0), *o)) for s, r, n, o in EARLIER),
    (0.5, False, 0.0, ()),  # the switch alone, no relabelling
    (-1.0, False, 1.0, ()),  # the default before the switch: the network's log-odds add to the mask
)
# The default's masks brought to the frame's size with other windows of the edge-following
# upsample (0: linear); the default's own is the segmenter's ``edge_radius``.
EDGES = (0.0, 0.005, 0.01)


def _digest(path: Path) -> str:
    return hashlib.blake2b(path.read_bytes(), digest_size=12).hexdigest()


def _label(switch: float, relabel: bool, net_weight: float, options=()) -> str:
    text = "animalnet," + (f"switch={switch:g}" if switch >= 0 else "no switch")
    text += ",relabel" if relabel else ""
    text += "".join(f" {k}={v:g}" for k, v in options)
    return text + (f",adds {net_weight:g}/2" if net_weight > 0 else "")


def run(sequences, load, cache, base: dict, preset, flow_size, out: Path, weights: Path) -> dict:
    """`grabcut`, the network alone and `animalnet` at each of `GRID` on every video. ``load(seq)``
    -> (frames, truth); ``base``: the tracker's options. {video: {label: result}}."""
    from video_quality import _save, curve_plot, overlay_sheet, say, scored, segmenter_flow
    from video_quality import segment_video as grabcut_video

    from zooctl.video.animalnet import AnimalNetSegmenter, weights_file
    from zooctl.video.flow import VideoFlow
    from zooctl.video.grabcut import resize_flows
    from zooctl.video.selftrain import at_frame_size, at_working_size, main_animal

    weights = weights_file(weights)
    seg = AnimalNetSegmenter(weights, **base)
    defaults = dict(seg.relabel_options)
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
            seg.feature_every = 1
            ev = np.asarray(seg.evidence(frames, flow))
            cpu = time.process_time() - c0
            if path is not None:
                _save(path, evidence=ev, cpu_s=np.float64(cpu))
        small_frames, small = at_working_size(frames, tracked, (sh, sw))

        def full(masks, radius=seg.edge_radius, frames=frames, small_frames=small_frames):
            return np.asarray(at_frame_size(masks, frames, small_frames, radius, seg.edge_eps), bool)

        res = {"grabcut": g}
        alone = full(np.stack([main_animal(e) for e in ev]), 0.0)
        res["network alone"] = scored(alone, truth, {"evidence_cpu_s": cpu})
        masks_by = {}
        for switch, relabel, net_weight, options in GRID:
            seg.feature_every, seg.switch_motion, seg.relabel, seg.net_weight = 3, switch, relabel, net_weight
            seg.relabel_options = {**defaults, **dict(options)}
            c0 = time.process_time()
            decided = seg.decide_near(small_frames, small, flow, seed_frame=g.get("seed_frame"))
            masks = full(decided)
            info = dict(seg.report["animalnet"], cpu_s=round(time.process_time() - c0, 2))
            res[_label(switch, relabel, net_weight, options)] = scored(masks, truth, info)
            masks_by[(switch, relabel, net_weight, options)] = masks
            if (switch, relabel, net_weight, options) == GRID[0]:
                for radius in EDGES:
                    label = _label(switch, relabel, net_weight, options) + f" edge_radius={radius:g}"
                    res[label] = scored(full(decided, radius), truth, info)
        results[seq] = res
        d = _label(*GRID[0])
        say(
            f"  {seq:14s} grabcut {g['J']:.3f}, network alone {res['network alone']['J']:.3f}, "
            + ", ".join(
                f"{k.split(',', 1)[1]} {v['J']:.3f}" for k, v in res.items() if k.startswith("animalnet")
            )
            + f"; motion margin {res[d].get('motion_margin')}, default {res[d].get('cpu_s')} CPU s"
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
