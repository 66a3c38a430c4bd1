"""Hard cases made from the shared real videos, `grabcut` against the default `animalnet`; used by
``bench/video.py --part hard``.

Each of the seven DAVIS videos (with its ground truth) becomes:

- ``pan``: a window half the frame's width pans at constant speed from around the animal on the
  first frame to the far side of the frame, so the animal leaves the view on many videos (a camera
  that loses it). Frames where the truth is empty must be stored empty.
- ``leave``: a window a third of the frame's width pans from around the animal to the far side over
  the first half of the clip and stays there: on most videos the animal leaves the view.
- ``fast``: every third frame only (the animal moves three times as far between frames: a fast
  animal, or a low frame rate).
- ``two``: a second, smaller animal: the next video's animal (with its own motion, cut out by its
  truth and scaled to a third of the main animal's area on the first frame) pasted into the corner
  of the frame farthest from the main one. The truth is the main animal only: it must be kept
  throughout and the second left out.
- ``chase``: as ``two``, but the second animal is dog-agility's dog, the fastest-moving of the seven
  (for dog-agility itself, the next video's animal): a second animal that moves more than the main
  one must not take its place.
- ``small``: the animal at a third of its size (a ninth of its area), cut out by its truth and pasted
  over the first frame with the animal painted out, its first-frame centre in place: a distant animal
  before a still camera.

The windows and the step of the first four were fixed before any run; ``chase`` was added after the
switch had been seen taking such a second animal, ``small`` later (its scale fixed before its run).
`animalnet`'s identity check, remnant rule and crop were designed after seeing these cases, so the
cases show what those do, not how they generalise.
J per frame as DAVIS counts it (a frame where both masks are empty counts 1, a mask on a frame
without the animal 0). Also counted: the frames without the animal, and how many were left empty.
Flow and the tracker's masks are cached as ``--part quality``'s. Written into the output folder:
``hard.md`` (the table), ``hard.json`` and ``overlays/hard-CASE-VIDEO.png``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

CASES = ("pan", "leave", "fast", "two", "chase", "small")
FASTEST = "dog-agility"


def make_case(case: str, frames: np.ndarray, truth: np.ndarray, other=None) -> tuple[np.ndarray, np.ndarray]:
    """(T, H, W, 3) frames and (T, H, W) truth -> the ``case``'s frames and truth; ``other``: another
    video's (frames, truth) for ``two``."""
    if case in ("two", "chase"):
        return _with_second_animal(frames, truth, *other)
    if case == "fast":
        return frames[::3].copy(), truth[::3].copy()
    if case == "small":
        return _small_animal(frames, truth)
    t, _, w = truth.shape
    ww = w // 2 if case == "pan" else w // 3
    xs = np.flatnonzero(truth[0].any(0))
    cx = float(xs.mean()) if len(xs) else w / 2
    x0 = int(np.clip(cx - ww / 2, 0, w - ww))
    x1 = 0 if cx > w / 2 else w - ww
    if case == "pan":
        pos = np.round(np.linspace(x0, x1, t)).astype(int)
    else:
        half = max(t // 2, 2)
        pos = np.concatenate([np.round(np.linspace(x0, x1, half)), np.full(t - half, x1)]).astype(int)
    return (
        np.stack([frames[i, :, p : p + ww] for i, p in enumerate(pos)]),
        np.stack([truth[i, :, p : p + ww] for i, p in enumerate(pos)]),
    )


def _small_animal(frames, truth, scale: float = 1.0 / 3.0) -> tuple[np.ndarray, np.ndarray]:
    """The animal at ``scale`` of its size (a ninth of its area at a third), cut out of each frame by
    its truth and pasted, its frame-0 centre in place, over frame 0 with the animal painted out
    (OpenCV's Telea inpainting): a distant animal moving as the original does, scaled, before a still
    camera (a background painted per frame would carry a blurred ghost of the animal along)."""
    import cv2

    t, h, w = truth.shape
    ys, xs = np.nonzero(truth[0])
    cy, cx = (ys.mean(), xs.mean()) if len(xs) else (h / 2, w / 2)
    oy, ox = int(round(cy * (1 - scale))), int(round(cx * (1 - scale)))
    sh, sw = max(round(h * scale), 1), max(round(w * scale), 1)
    hole = cv2.dilate(truth[0].astype(np.uint8), np.ones((9, 9), np.uint8))
    background = cv2.inpaint(np.ascontiguousarray(frames[0]), hole, 5, cv2.INPAINT_TELEA)
    out = np.repeat(background[None], t, 0)
    small_truth = np.zeros_like(truth)
    for i in range(t):
        fs = cv2.resize(frames[i], (sw, sh), interpolation=cv2.INTER_AREA)
        ms = cv2.resize(truth[i].astype(np.uint8), (sw, sh), interpolation=cv2.INTER_NEAREST) > 0
        y0, x0, y1, x1 = max(oy, 0), max(ox, 0), min(oy + sh, h), min(ox + sw, w)
        sub = ms[y0 - oy : y1 - oy, x0 - ox : x1 - ox]
        out[i, y0:y1, x0:x1][sub] = fs[y0 - oy : y1 - oy, x0 - ox : x1 - ox][sub]
        small_truth[i, y0:y1, x0:x1] = sub
    return out, small_truth


def _with_second_animal(frames, truth, frames_b, truth_b) -> tuple[np.ndarray, np.ndarray]:
    import cv2

    t, h, w = truth.shape
    area_a, area_b = max(int(truth[0].sum()), 1), max(int(truth_b[0].sum()), 1)
    s = float(np.sqrt(area_a / area_b / 3.0))
    ys, xs = np.nonzero(truth[0])
    cy, cx = (ys.mean(), xs.mean()) if len(xs) else (h / 2, w / 2)
    yb, xb = np.nonzero(truth_b[0])
    by, bx = (yb.mean() * s, xb.mean() * s) if len(xb) else (0.0, 0.0)
    # the second animal's centre on the first frame: a quarter of the way in from the far corner
    ty = h * (0.75 if cy < h / 2 else 0.25)
    tx = w * (0.8 if cx < w / 2 else 0.2)
    oy, ox = int(round(ty - by)), int(round(tx - bx))
    out = frames.copy()
    for i in range(t):
        j = i % len(frames_b)
        fb = cv2.resize(frames_b[j], None, fx=s, fy=s, interpolation=cv2.INTER_AREA)
        mb = (
            cv2.resize(
                truth_b[j].astype(np.uint8), (fb.shape[1], fb.shape[0]), interpolation=cv2.INTER_NEAREST
            )
            > 0
        )
        y0, x0 = max(oy, 0), max(ox, 0)
        y1, x1 = min(oy + fb.shape[0], h), min(ox + fb.shape[1], w)
        if y1 <= y0 or x1 <= x0:
            continue
        sub = mb[y0 - oy : y1 - oy, x0 - ox : x1 - ox]
        region = out[i, y0:y1, x0:x1]
        region[sub] = fb[y0 - oy : y1 - oy, x0 - ox : x1 - ox][sub]
    # the main animal stays in front where the two overlap
    out[truth] = frames[truth]
    return out, truth.copy()


def run(sequences, load, cache, base: dict, preset, flow_size, out: Path, weights) -> dict:
    """``load(seq)`` -> (frames, truth). {case: {video: {segmenter: result}}}."""
    from video_quality import overlay_sheet, say, scored, segmenter_flow
    from video_quality import segment_video as grabcut_video

    from zooctl.video.animalnet import AnimalNetSegmenter
    from zooctl.video.flow import VideoFlow
    from zooctl.video.grabcut import resize_flows
    from zooctl.video.selftrain import at_frame_size, at_working_size

    seg = AnimalNetSegmenter(weights, **base)
    results: dict = {case: {} for case in CASES}
    for k, seq in enumerate(sequences):
        frames0, truth0 = load(seq)
        for case in CASES:
            other = None
            if case == "two" or (case == "chase" and (seq == FASTEST or FASTEST not in sequences)):
                other = load(sequences[(k + 1) % len(sequences)])
            elif case == "chase":
                other = load(FASTEST)
            frames, truth = make_case(case, frames0, truth0, other)
            t, h, w = frames.shape[:3]
            tracked, g = grabcut_video(f"{case}-{seq}", frames, truth, cache, base, {}, preset, flow_size)
            flow, _ = segmenter_flow(cache, seg, frames, preset, flow_size)
            sw, sh = seg.flow_size(w, h)
            if tuple(flow.forward.shape[1:3]) != (sh, sw):
                flow = VideoFlow(
                    *(resize_flows(f, sw, sh, frames) for f in (flow.forward, flow.backward)), None, None
                )
            small_frames, small = at_working_size(frames, tracked, (sh, sw))
            got = seg.decide_near(small_frames, small, flow, seed_frame=g.get("seed_frame"))
            masks = np.asarray(at_frame_size(got, frames, small_frames, seg.edge_radius, seg.edge_eps), bool)
            a = scored(masks, truth, dict(seg.report["animalnet"]))
            absent = ~truth.reshape(t, -1).any(1)
            res = {"grabcut": g, "animalnet": a, "frames_without_animal": int(absent.sum())}
            for name, m in (("grabcut", np.asarray(tracked, bool)), ("animalnet", masks)):
                res[name]["left_empty"] = int((absent & ~m.reshape(t, -1).any(1)).sum())
            results[case][seq] = res
            say(
                f"  {case:5s} {seq:14s} frames {t:3d} (no animal on {int(absent.sum())}): grabcut "
                f"{g['J']:.3f}, animalnet {a['J']:.3f} (left empty {res['grabcut']['left_empty']} / "
                f"{res['animalnet']['left_empty']}), replaced {a['network_replaced_tracker']}"
            )
            overlay_sheet(out / "overlays" / f"hard-{case}-{seq}.png", frames, masks, truth, a["per_frame"])
    return results


def table(results: dict) -> str:
    """Markdown: per case and video, J of both and the frames without the animal left empty."""
    rows = [
        "| case | video | frames | without the animal | `grabcut` J | default `animalnet` J | left empty, `grabcut` / `animalnet` |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    for case, per in results.items():
        for seq, r in per.items():
            rows.append(
                f"| {case} | {seq} | {r['grabcut']['frames']} | {r['frames_without_animal']} | "
                f"{r['grabcut']['J']:.3f} | {r['animalnet']['J']:.3f} | "
                f"{r['grabcut']['left_empty']} / {r['animalnet']['left_empty']} |"
            )
        g = np.mean([r["grabcut"]["J"] for r in per.values()])
        a = np.mean([r["animalnet"]["J"] for r in per.values()])
        n = sum(r["frames_without_animal"] for r in per.values())
        eg = sum(r["grabcut"]["left_empty"] for r in per.values())
        ea = sum(r["animalnet"]["left_empty"] for r in per.values())
        rows.append(f"| **{case}** | **mean** | | {n} | **{g:.3f}** | **{a:.3f}** | {eg} / {ea} |")
    return "\n".join(rows) + "\n"
