"""Mask quality of the automatic segmenter on the shared real videos, with settings chosen
leave-one-video-out; used by ``bench/video.py --part quality``.

Each video is decoded at the default size, its flow computed as `video add` computes it (DIS at
its default size, resized to the size GrabCut works at) and segmented with no box by the `grabcut`
segmenter, once at its defaults and once per other value of each grid setting (the rest at their
defaults). Flow and masks are cached on disk, keyed by the frames, the settings and the source of
the modules the masks depend on, so a rerun (another plot, another table) segments nothing again.

Written into the output folder: ``quality.md`` (the table), ``quality.json``, ``curves/VIDEO.png``
(J per frame) and ``overlays/VIDEO.png`` (six frames: the automatic mask's outline in green, the
ground truth's in magenta).
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import time
from functools import partial
from pathlib import Path

import cv2
import numpy as np

REPO = Path(__file__).resolve().parents[1]
# the modules the masks depend on: a change to any of them makes the cached masks stale
SOURCES = [
    REPO / "zooctl" / "video" / f for f in ("grabcut.py", "cues.py", "hint.py", "localise.py", "flow.py")
] + [REPO / "zooctl" / "embed" / "effnet_numpy.py"]
# the videos the segmenter's defaults were developed on (its other videos are unseen by them)
DEVELOPED_ON = ("blackswan", "dog", "cows")
# what the grid measures: (setting, values); each is varied alone, the others at their defaults
GRID: dict[str, tuple] = {
    "core_quantile": (0.0, 0.5, 0.75),
    "min_agreement": (0.15, 0.3, 0.5),
}


def _digest(*parts) -> str:
    h = hashlib.blake2b(digest_size=12)
    for p in parts:
        h.update(p if isinstance(p, bytes) else json.dumps(p, sort_keys=True, default=str).encode())
        h.update(b"\0")
    return h.hexdigest()


def source_digest() -> str:
    return _digest(*(p.read_bytes() for p in SOURCES))


def _save(path: Path, **arrays) -> None:
    """Written whole or not at all (a killed run leaves no half file to be read as a result)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    with open(tmp, "wb") as f:
        np.savez(f, **arrays)
    os.replace(tmp, path)


class Cache:
    """Flow and masks on disk under ``root`` (None: nothing cached)."""

    def __init__(self, root: Path | None) -> None:
        self.root = root
        self.sources = source_digest()

    def flow(self, frames: np.ndarray, size: tuple[int, int], make_estimator):
        """`VideoFlow` (forward, backward) of ``frames`` resized to ``size`` (w, h), as `video add`
        hands it to the segmenter."""
        from zooctl.video.flow import VideoFlow, compute_video_flow, resize_flow

        est = make_estimator()
        key = _digest(
            "flow",
            _frames_digest(frames),
            size,
            type(est).__name__,
            getattr(est, "preset", None),
            getattr(est, "max_size", None),
            self.sources,
        )
        path = None if self.root is None else self.root / f"flow-{key}.npz"
        if path is not None and path.exists():
            with np.load(path) as z:
                return VideoFlow(z["forward"], z["backward"], None, None)
        vf = compute_video_flow(est, frames)
        w, h = size
        same = tuple(vf.forward.shape[1:3]) == (h, w)
        fwd = vf.forward if same else np.stack([resize_flow(f, w, h) for f in vf.forward])
        bwd = vf.backward if same else np.stack([resize_flow(f, w, h) for f in vf.backward])
        if path is not None:
            _save(path, forward=fwd, backward=bwd)
        return VideoFlow(fwd, bwd, None, None)

    def masks(self, frames: np.ndarray, flow_key: str, options: dict, box, segment):
        """(masks, info) for ``options``; ``segment()`` -> (masks, info) runs on a miss."""
        key = _digest("masks", _frames_digest(frames), flow_key, options, box, self.sources)
        path = None if self.root is None else self.root / f"masks-{key}.npz"
        if path is not None and path.exists():
            with np.load(path) as z:
                shape = tuple(z["shape"])
                masks = np.unpackbits(z["bits"], count=int(np.prod(shape))).reshape(shape).astype(bool)
                return masks, json.loads(str(z["info"]))
        masks, info = segment()
        if path is not None:
            _save(path, bits=np.packbits(masks), shape=np.array(masks.shape), info=np.array(json.dumps(info)))
        return masks, info


_DIGESTS: dict[int, tuple[np.ndarray, str]] = {}


def _frames_digest(frames: np.ndarray) -> str:
    hit = _DIGESTS.get(id(frames))
    if hit is not None and hit[0] is frames:
        return hit[1]
    d = _digest(str(frames.shape), np.ascontiguousarray(frames).tobytes())
    _DIGESTS.clear()
    _DIGESTS[id(frames)] = (frames, d)
    return d


def configs(grid: dict[str, tuple], defaults: dict) -> list[dict]:
    """The settings to run: {} (all defaults) and each grid value that is not its default."""
    out: list[dict] = [{}]
    for k, values in grid.items():
        out += [{k: v} for v in values if v != defaults[k]]
    return out


def scores_by_value(results: dict, grid: dict[str, tuple], defaults: dict, k: str) -> dict:
    """{value: {video: J}} of setting ``k`` (its default is the all-defaults run)."""
    return {
        v: {seq: r[_label({} if v == defaults[k] else {k: v})]["J"] for seq, r in results.items()}
        for v in grid[k]
    }


def _label(options: dict) -> str:
    return ",".join(f"{k}={v}" for k, v in sorted(options.items())) or "default"


def segment_video(name, frames, truth, cache: Cache, base: dict, options: dict, preset, flow_size, box=None):
    """Segment one video with ``base`` + ``options`` (cached); J per frame and what the segmenter
    reported."""
    from zooctl.plugins import get_registry

    spec = get_registry().get("segmenter", "grabcut")
    seg = spec.create(**base, **options)
    flow, flow_key = segmenter_flow(cache, seg, frames, preset, flow_size)

    def run():
        t0 = time.perf_counter()
        masks = seg.segment(frames, box=box, flow=flow)
        how = seg.report.get("seeding", [])
        return np.asarray(masks, bool), {
            "segment_s": time.perf_counter() - t0,
            "seed_frame": seg.report.get("seed_frame"),
            "re_seeded": [i for i, s in enumerate(how) if s == "re-seeded"],
            "empty": [i for i, s in enumerate(how) if s == "empty"],
            "classes": [c["name"] for c in seg.report.get("animal_classes", [])],
        }

    masks, info = cache.masks(frames, flow_key, {**base, **options}, box, run)
    return masks, scored(masks, truth, info)


def segmenter_flow(cache: Cache, seg, frames, preset, flow_size):
    """(flow, its cache key): DIS with ``preset`` (at most ``flow_size`` px) resized to the size
    ``seg`` works at, as `video add` hands it over."""
    from zooctl.video.flow import DISFlow

    h, w = frames.shape[1:3]
    size = seg.flow_size(w, h)

    def estimator():
        return DISFlow(preset) if flow_size is None else DISFlow(preset, max_size=flow_size)

    return cache.flow(frames, size, estimator), _digest(preset, flow_size, size)


def scored(masks, truth, info: dict) -> dict:
    """J of ``masks`` against ``truth``: per frame, mean and worst frame, with ``info``."""
    from zooctl.video.mask_quality import per_frame_j

    j = per_frame_j(masks, truth)
    return {"frames": len(j), "J": float(j.mean()), "J_min": float(j.min()), "per_frame": j.tolist(), **info}


def say(text: str) -> None:
    """A progress line on stderr (stdout may carry the table)."""
    print(text, file=sys.stderr, flush=True)


def run_settings(seq, frames, truth, runs: list[dict], segment, label, line, overlay: Path) -> dict:
    """{label(options): result} of each of ``runs`` on one video: ``segment(seq, frames, truth,
    options=options)`` -> (masks, result), a progress line ``line(seq, label, result)`` each, and the
    all-defaults run's `overlay_sheet` in ``overlay``."""
    results = {}
    for options in runs:
        masks, r = segment(seq, frames, truth, options=options)
        results[label(options)] = r
        if not options:
            overlay_sheet(overlay, frames, masks, truth, r["per_frame"])
        say(line(seq, label(options), r))
    return results


def _progress_line(seq: str, label: str, r: dict) -> str:
    return (
        f"  {seq:14s} {label:22s} J={r['J']:.3f} (min {r['J_min']:.3f}) {r['frames']} frames, "
        f"segment {r['segment_s']:.1f}s, seed frame {r['seed_frame']}, {len(r['re_seeded'])} re-seeded, "
        f"{len(r['empty'])} empty, saw {', '.join(r['classes'])}"
    )


def run_real(sequences, load, cache: Cache, base: dict, grid: dict, preset, flow_size, out: Path) -> dict:
    """Every video at every grid setting; curves and overlays at the defaults. ``load(seq)`` ->
    (frames, truth). {video: {label: result}}."""
    from zooctl.plugins import get_registry

    defaults = {k: getattr(get_registry().get("segmenter", "grabcut").create(**base), k) for k in grid}
    runs = configs(grid, defaults)
    segment = partial(segment_video, cache=cache, base=base, preset=preset, flow_size=flow_size)
    results: dict = {}
    for seq in sequences:
        frames, truth = load(seq)
        overlay = out / "overlays" / f"{seq}.png"
        results[seq] = run_settings(seq, frames, truth, runs, segment, _label, _progress_line, overlay)
        curves = {label: r["per_frame"] for label, r in results[seq].items()}
        curve_plot(out / "curves" / f"{seq}.png", seq, curves, results[seq]["default"])
    return {"defaults": defaults, "grid": {k: list(v) for k, v in grid.items()}, "videos": results}


def leave_one_out_table(report: dict) -> tuple[str, dict]:
    """The markdown table (in-sample and leave-one-out J side by side) and its numbers."""
    from zooctl.video.mask_quality import leave_one_out

    res, grid, defaults = report["videos"], report["grid"], report["defaults"]
    seqs = list(res)
    loo = {}
    for k in grid:
        loo[k] = leave_one_out(scores_by_value(res, grid, defaults, k), prefer=defaults[k])
    # the whole grid as one choice: any single setting changed, or none
    loo["any"] = leave_one_out({lab: {s: res[s][lab]["J"] for s in seqs} for lab in res[seqs[0]]}, "default")
    head = ["video", "frames", "default J (worst frame)"]
    for k in grid:
        head += [f"`{k}` best on all 7 ({loo[k].best}), in-sample", f"`{k}` leave-one-out (value picked)"]
    head += ["any grid setting, leave-one-out (picked)"]
    rows = ["| " + " | ".join(head) + " |", "|" + "---|" * 1 + "---:|" * (len(head) - 1)]
    for s in seqs:
        d = res[s]["default"]
        name = f"{s}{' *' if s in DEVELOPED_ON else ''}"
        cells = [name, str(d["frames"]), f"{d['J']:.3f} ({d['J_min']:.3f})"]
        for k in grid:
            cells += [f"{loo[k].in_sample[s]:.3f}", f"{loo[k].held_out[s]:.3f} ({loo[k].picked[s]})"]
        cells += [f"{loo['any'].held_out[s]:.3f} ({loo['any'].picked[s]})"]
        rows.append("| " + " | ".join(cells) + " |")
    mean = float(np.mean([res[s]["default"]["J"] for s in seqs]))
    cells = ["**mean**", str(sum(res[s]["default"]["frames"] for s in seqs)), f"**{mean:.3f}**"]
    for k in grid:
        cells += [f"{loo[k].in_sample_mean:.3f}", f"**{loo[k].held_out_mean:.3f}**"]
    cells += [f"**{loo['any'].held_out_mean:.3f}**"]
    rows.append("| " + " | ".join(cells) + " |")
    numbers = loo_numbers(loo)
    numbers["default_mean"] = mean
    note = (
        "\n\n`*`: developed on (the defaults were chosen looking at it). Per setting, the other grid "
        "values are run with everything else at its default; leave-one-out: the value with the best "
        "mean J on the other six videos (ties keep the default), scored on the seventh.\n"
    )
    return "\n".join(rows) + note, numbers


def loo_numbers(loo: dict) -> dict:
    """{setting: its leave-one-out choice as JSON} of {setting: `LeaveOneOut`}."""
    return {
        k: {
            "best_on_all": v.best,
            "in_sample": v.in_sample,
            "in_sample_mean": v.in_sample_mean,
            "picked": v.picked,
            "held_out": v.held_out,
            "held_out_mean": v.held_out_mean,
        }
        for k, v in loo.items()
    }


def curve_plot(path: Path, title: str, curves: dict[str, list[float]], default: dict) -> None:
    """J per frame, one line per setting (the defaults thick and black), seed frame and re-seeded
    frames marked."""
    w, h, left, bottom, top = 760, 300, 44, 26, 22
    img = np.full((h, w, 3), 255, np.uint8)
    pw, ph = w - left - 10, h - bottom - top
    n = max(len(c) for c in curves.values())

    def xy(i, j):
        return int(left + pw * i / max(n - 1, 1)), int(top + ph * (1 - j))

    for g in (0, 0.25, 0.5, 0.75, 1.0):
        cv2.line(img, xy(0, g), xy(n - 1, g), (225, 225, 225), 1)
        cv2.putText(img, f"{g:.2f}", (4, xy(0, g)[1] + 4), cv2.FONT_HERSHEY_SIMPLEX, 0.35, (90, 90, 90), 1)
    for i in range(0, n, 10):
        cv2.putText(img, str(i), (xy(i, 0)[0] - 5, h - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.35, (90, 90, 90), 1)
    colours = [(31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189), (140, 86, 75)]
    legend = []
    for k, (lab, c) in enumerate(sorted(curves.items(), key=lambda kv: kv[0] != "default")):
        col = (0, 0, 0) if lab == "default" else colours[(k - 1) % len(colours)]
        pts = np.array([xy(i, j) for i, j in enumerate(c)], np.int32)
        cv2.polylines(img, [pts], False, col, 2 if lab == "default" else 1, cv2.LINE_AA)
        legend.append((f"{lab} {np.mean(c):.3f}", col))
    for i in default.get("re_seeded", []):
        cv2.drawMarker(img, xy(i, default["per_frame"][i]), (0, 0, 200), cv2.MARKER_TRIANGLE_UP, 8, 1)
    s = default.get("seed_frame")
    if s is not None:
        cv2.drawMarker(img, xy(s, default["per_frame"][s]), (0, 0, 0), cv2.MARKER_DIAMOND, 10, 2)
    cv2.putText(
        img,
        f"{title}: J per frame (diamond: seed frame, triangles: re-seeded)",
        (left, 15),
        cv2.FONT_HERSHEY_SIMPLEX,
        0.42,
        (0, 0, 0),
        1,
    )
    for k, (text, col) in enumerate(legend):
        cv2.putText(
            img, text, (left + 6, top + 14 + 13 * k), cv2.FONT_HERSHEY_SIMPLEX, 0.36, col, 1, cv2.LINE_AA
        )
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), img[..., ::-1])


def overlay_sheet(path: Path, frames, masks, truth, per_frame=None, tiles: int = 6, width: int = 427) -> None:
    """``tiles`` frames spread over the video, each at ``width`` px: the automatic mask's outline in
    green, the ground truth's in magenta, frame number and J in the corner."""
    out = []
    for i in np.linspace(0, len(frames) - 1, tiles).astype(int):
        f = np.ascontiguousarray(frames[i])
        s = width / f.shape[1]
        size = (width, round(f.shape[0] * s))
        f = cv2.resize(f, size, interpolation=cv2.INTER_AREA)
        for m, col in ((truth[i], (255, 0, 255)), (masks[i], (0, 255, 0))):
            small = cv2.resize(np.asarray(m, np.uint8), size, interpolation=cv2.INTER_NEAREST)
            c, _ = cv2.findContours(small, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
            cv2.drawContours(f, c, -1, col, 2 if col[1] == 255 and col[0] == 0 else 1, cv2.LINE_AA)
        text = f"{i}" + ("" if per_frame is None else f"  J {per_frame[i]:.2f}")
        cv2.rectangle(f, (0, 0), (110, 18), (0, 0, 0), -1)
        cv2.putText(f, text, (4, 13), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
        out.append(f)
    cols = 3
    rows = [np.hstack(out[r : r + cols]) for r in range(0, len(out), cols)]
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), np.vstack(rows)[..., ::-1])
