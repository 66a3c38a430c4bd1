"""Numbers `video show` prints: per-frame mask coverage and boxes, flow magnitude statistics."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from typing import Any

import numpy as np


def video_stats(rec) -> dict[str, Any]:
    """A `VideoRecord` with masks and flow -> JSON-ready statistics."""
    from ..store.videos import boxes_of

    t = len(rec.masks)
    coverage = rec.masks.reshape(t, -1).mean(1)
    mag = np.linalg.norm(rec.flow_forward, axis=-1)
    occ = np.concatenate([rec.occlusion_forward.reshape(-1), rec.occlusion_backward.reshape(-1)])
    return _stats(
        rec.segmenter,
        coverage,
        boxes_of(rec.masks),
        float(mag.mean()),
        float(np.percentile(mag, 99)),
        float(mag.max()),
        float(occ.mean()),
        mag.reshape(t - 1, -1).mean(1),
    )


def stored_video_stats(f) -> dict[str, Any]:
    """`video_stats` of a stored video's file (an open ``h5py.File``), read a frame at a time: a long
    video is never in memory at once. The flow's 99th percentile comes from 0.001 px bins."""
    import json

    masks, fwd = f["masks"], f["flow/forward"]
    occs = (f["flow/occlusion_forward"], f["flow/occlusion_backward"])
    coverage = np.array([float(masks[i].mean()) for i in range(len(masks))])
    per_frame, occluded = [], 0
    for i in range(len(fwd)):
        mag = _magnitude(fwd[i])
        per_frame.append(float(mag.mean()))
        occluded += sum(int(np.count_nonzero(o[i])) for o in occs)
    n = max(1, len(fwd) * int(np.prod(fwd.shape[1:3])))
    p99, top = magnitude_percentile(lambda: (fwd[i] for i in range(len(fwd))), 0.99)
    return _stats(
        json.loads(f.attrs["segmenter"]),
        coverage,
        f["boxes"][()],
        float(np.mean(per_frame)),
        p99,
        top,
        occluded / (2 * n),
        np.asarray(per_frame),
    )


MAX_MAGNITUDE = 4096.0  # px: past any real frame's diagonal; a damaged file's huge values count as this


def _magnitude(flow: np.ndarray) -> np.ndarray:
    """(H, W) flow magnitudes in pixels of one (H, W, 2) flow frame, non-finite ones as the maximum."""
    mag = np.linalg.norm(np.asarray(flow, np.float32), axis=-1)
    return np.nan_to_num(np.minimum(mag, MAX_MAGNITUDE), nan=MAX_MAGNITUDE)


def magnitude_percentile(
    flows: Callable[[], Iterable[np.ndarray]], q: float, step: float = 1e-3
) -> tuple[float, float]:
    """(q-quantile, maximum) of the magnitudes of the flow frames (each (H, W, 2)) ``flows()``
    yields, seen one at a time (two passes: the maximum sizes the histogram), the quantile from
    ``step`` px bins: no more than one frame in memory."""
    top, n = 0.0, 0
    for flow in flows():
        mag = _magnitude(flow)
        top, n = max(top, float(mag.max(initial=0.0))), n + mag.size
    if n == 0:
        return 0.0, 0.0
    hist = np.zeros(int(top / step) + 2, np.int64)
    for flow in flows():
        hist += np.bincount((_magnitude(flow) / step).astype(np.int64).ravel(), minlength=len(hist))[
            : len(hist)
        ]
    return float(np.searchsorted(np.cumsum(hist), q * n)) * step, top


def _stats(seg, coverage, boxes, mean, p99, top, occluded, per_frame) -> dict[str, Any]:
    seg = seg or {}
    keys = (
        "seeding",
        "seed_frame",
        "seeds_tried",
        "box_frame",
        "box_use",
        "animal_classes",
        "animals_seen",
        "empty_frames",
        "small_frames",
        "animalnet",
        "self_training",
        "colour_snap",
        "animal_check",
    )
    return {
        "seeding": {k: seg[k] for k in keys if k in seg} or None,
        "mask_coverage": [round(float(c), 5) for c in coverage],
        "boxes": np.asarray(boxes).tolist(),
        "flow": {
            "mean_magnitude": mean,
            "p99_magnitude": p99,
            "max_magnitude": top,
            "occluded_fraction": occluded,
            "per_frame_mean_magnitude": [round(float(m), 4) for m in per_frame],
        },
    }


def seeding_lines(seeding: dict[str, Any] | None) -> list[str]:
    """What `video show` prints about how the masks were seeded and what the localiser saw."""
    if not seeding:
        return []
    out = []
    how = seeding.get("seeding") or []
    if how:
        counts = {k: how.count(k) for k in ("box", "localiser", "re-seeded", "tracked", "network", "empty")}
        seeded = counts["network"] < len(how)  # else the network's animal replaced every tracked mask
        out.append(
            "seeding: "
            + ", ".join(f"{n} {k}" for k, n in counts.items() if n)
            + (f" (first seed on frame {seeding.get('seed_frame')})" if seeded else "")
        )
    if seeding.get("box_use") == "chose the animal":
        out.append(
            f"the box on frame {seeding.get('box_frame')} chose the animal; the localiser seeded it "
            "where it saw it most surely"
        )
    elif seeding.get("box_use") == "seeded":
        out.append(f"the box on frame {seeding.get('box_frame')} seeded the masks")
    tried = seeding.get("seeds_tried")
    if tried:
        each = ", ".join(f"{k} ({v:.2f})" for k, v in tried.items())
        out.append(
            f"seed frames tried (agreement with the network): {each}; kept {seeding.get('seed_frame')}"
        )
    classes = seeding.get("animal_classes") or []
    if classes:
        seen = ", ".join(f"{c['name']} {c['probability']:.0%}" for c in classes)
        n = seeding.get("animals_seen", 0)
        extra = f"; {n} animal-like regions at once, the one with most evidence kept" if n > 1 else ""
        out.append(f"localiser saw: {seen}{extra}")
    net = seeding.get("animalnet")
    if net:
        margin = net.get("motion_margin")
        moved = (
            "the network saw no animal"
            if margin is None
            else f"the network's animal moved against the camera {margin:+.2f}% of the width more than the tracked mask"
        )
        verdict = (
            "its animal replaced the tracker's masks"
            if net.get("network_replaced_tracker")
            else "the tracker's masks kept"
        )
        if net.get("identity_kept_tracker"):
            verdict += " (the animal moving most was not the tracked one)"
        out.append(f"animalnet: {moved}: {verdict}")
        cover = net.get("part_cover")
        if cover is not None:
            out.append(
                f"the network's part holding the tracked region covers {cover:.2f} times its area"
                + (
                    ": the tracker held a piece of the animal, the part replaced it"
                    if net.get("replaced_as_part")
                    else ""
                )
            )
        if net.get("crop"):
            x, y, w, h = net["crop"]
            out.append(
                f"decided on the part of the frame the animal keeps to: {w}x{h} at ({x}, {y}), working size"
            )
        if net.get("remnants_dropped"):
            out.append(
                f"left empty as remnants of the tracker (far smaller than the animal, not at the edge): "
                f"frames {_ranges(net['remnants_dropped'])}"
            )
    if (seeding.get("self_training") or {}).get("changed") is not None:
        out.append(
            f"relabelled by a classifier learned from this video: {seeding['self_training']['changed']:.1%} "
            "of mask pixels changed"
        )
    snap = seeding.get("colour_snap")
    if snap and snap.get("separation_gain") is not None:
        out.append(
            f"snapped to the animal's colours (GrabCut seeded by each mask): separation "
            f"{snap['separation_gain']:+.3f} at the median frame, "
            + ("kept" if snap.get("snapped") else f"not kept (kept above {snap['min_gain']:+.3f})")
        )
    if seeding.get("empty_frames"):
        out.append(
            f"no animal in frames {_ranges(seeding['empty_frames'])} (stored empty; the fit skips them)"
        )
    if seeding.get("small_frames"):
        out.append(f"masks under 0.1% of the frame in frames {_ranges(seeding['small_frames'])}")
    check = seeding.get("animal_check")
    if check:
        out.append(
            f"animal check: the classifier gives the masked parts {check['looks']:.0%} animal (median of "
            f"{len(check['frames'])} frames), "
            + (
                "no localiser to count regions"
                if check["regions"] is None
                else f"{check['regions']} animal-like region(s) where it seeded"
            )
            + ", "
            f"{check['empty_share']:.0%} of frames empty: "
            + ("UNSURE the masks hold an animal" if check["unsure"] else "an animal")
            + (
                " (made now: the video was stored before the check; not stored)"
                if check.get("made_now")
                else ""
            )
        )
    return out


def _ranges(frames: list[int]) -> str:
    """[1, 2, 3, 7] -> "1-3, 7"."""
    parts, start = [], None
    for i, f in enumerate(frames):
        if start is None:
            start = f
        if i + 1 == len(frames) or frames[i + 1] != f + 1:
            parts.append(str(start) if start == f else f"{start}-{f}")
            start = None
    return ", ".join(parts)
