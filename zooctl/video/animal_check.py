"""Is there an animal in the automatic masks? A check `video add` runs on what a segmenter made.

An automatic segmenter always finds something: given a clip of rocks, water or a landscape it
tracks whatever the localiser liked best, and the fit then reconstructs a rock. Two things tell
such masks apart from an animal's (BENCHMARKS.md, "A video with no animal"):

- ``looks``: what the shipped ImageNet classifier (`zooctl.video.localise.Localiser`) makes of the
  masks' crops. On `LOOK_FRAMES` frames spread over the video, the square around each frame's mask
  (`CROP_MARGIN` times its longer side) is classified and the probability of all animal classes
  together read; a frame whose mask is empty counts 0. ``looks`` is their median.
- ``regions``: how many separate animal-like regions the localiser saw at once where it seeded
  (the tracker's ``animals_seen``): one on a video of an animal, several weak ones on a scene
  without any.

The masks are ``unsure`` when the localiser saw `MIN_REGIONS` or more regions and either the crops
do not look like an animal (``looks`` under `MIN_LOOKS`) or the segmenter left more than
`MAX_EMPTY_SHARE` of the frames empty. Rendered and stylised animals often look like no ImageNet
class, so ``looks`` alone would flag them; the localiser's one clear region clears them. A check,
not a refusal: `video add` says so and stores the masks, `zooctl fit` repeats it in its notes.
"""

from __future__ import annotations

from typing import Any

import numpy as np

LOOK_FRAMES = 6  # frames classified, spread over the video
CROP_MARGIN = 1.25  # the classified square's side, in the mask's longer sides
CROP_WIDTH = 224  # the classifier's input for a crop (its training size)
# Chosen leave-one-video-out on 55 videos of an animal and 17 without one (BENCHMARKS.md)
MIN_REGIONS = 2
MIN_LOOKS = 0.525
MAX_EMPTY_SHARE = 0.3


def look_frames(n: int, count: int = LOOK_FRAMES) -> np.ndarray:
    """(k,) the frames of an ``n``-frame video the check classifies."""
    return np.unique(np.linspace(0, n - 1, min(count, n)).astype(int))


def mask_crop(frame: np.ndarray, mask: np.ndarray, margin: float = CROP_MARGIN) -> np.ndarray | None:
    """The square of ``frame`` (H, W, 3) around ``mask`` (H, W) bool, ``margin`` times the mask's
    longer side (cut by the frame's edges); None for an empty mask."""
    ys, xs = np.nonzero(mask)
    if len(ys) == 0:
        return None
    h, w = mask.shape
    cy, cx = (ys.min() + ys.max()) / 2.0, (xs.min() + xs.max()) / 2.0
    half = max(int(ys.max() - ys.min()), int(xs.max() - xs.min()), 32) * margin / 2.0
    y0, y1 = int(max(0, cy - half)), int(min(h, cy + half))
    x0, x1 = int(max(0, cx - half)), int(min(w, cx + half))
    return np.ascontiguousarray(frame[y0:y1, x0:x1])


def crop_looks(frames: Any, masks: Any, localiser=None, empty=()) -> tuple[np.ndarray, list[float]]:
    """The frames `look_frames` picks from ``frames`` (T, H, W, 3) uint8 and ``masks`` (T, H, W)
    (arrays or a store's lazy views), and for each the animal probability of its mask's crop (0
    where the mask is empty, or its frame is in ``empty``: stored empty)."""
    from .localise import Localiser

    loc = localiser or Localiser(width=CROP_WIDTH)
    sel = look_frames(len(masks))
    looks = []
    for t in sel:
        if int(t) in empty:
            looks.append(0.0)
            continue
        crop = mask_crop(np.asarray(frames[int(t)]), np.asarray(masks[int(t)], bool))
        looks.append(0.0 if crop is None else round(float(loc.evidence(crop).animal_prob), 4))
    return sel, looks


def check_animal(frames: Any, masks: Any, report: dict[str, Any], localiser=None) -> dict[str, Any]:
    """The check of automatic ``masks`` (T, H, W) of ``frames`` (T, H, W, 3) uint8, given the
    segmenter's ``report`` (its ``animals_seen`` and ``empty_frames``): ``looks``, the classified
    frames and each one's look, ``regions``, ``empty_share`` and ``unsure`` (module docstring).
    A segmenter that reports no ``animals_seen`` (not the localiser's tracker) is never unsure:
    the rule was chosen with it."""
    sel, per_frame = crop_looks(frames, masks, localiser, set(report.get("empty_frames") or []))
    looks = float(np.median(per_frame))
    regions = report.get("animals_seen")
    empty_share = len(report.get("empty_frames") or []) / max(len(masks), 1)
    unsure = (
        regions is not None
        and int(regions) >= MIN_REGIONS
        and (looks < MIN_LOOKS or empty_share > MAX_EMPTY_SHARE)
    )
    return {
        "looks": round(looks, 4),
        "frames": [int(t) for t in sel],
        "looks_per_frame": per_frame,
        "regions": None if regions is None else int(regions),
        "empty_share": round(empty_share, 4),
        "unsure": bool(unsure),
        "rule": {"min_regions": MIN_REGIONS, "min_looks": MIN_LOOKS, "max_empty_share": MAX_EMPTY_SHARE},
    }


def unsure_line(check: dict[str, Any] | None, name: str) -> str | None:
    """What to tell a user whose masks the check is unsure of (None when it is not)."""
    if not check or not check.get("unsure"):
        return None
    why = []
    if check["looks"] < check["rule"]["min_looks"]:
        why.append(
            f"the classifier gives the masked parts {check['looks']:.0%} animal "
            f"(an animal's: {check['rule']['min_looks']:.1%} or more)"
        )
    if check["empty_share"] > check["rule"]["max_empty_share"]:
        why.append(f"{check['empty_share']:.0%} of the frames have no mask")
    return (
        f"warning: {name}'s masks may not hold an animal: {' and '.join(why)}, and the localiser saw "
        f"{check['regions']} animal-like regions, none clearly. Look at `zooctl video show {name}`; "
        "if the animal is there, add the video again with --box x,y,w,h around it or your own --masks"
    )


def stored_animal_check(rec: Any) -> dict[str, Any] | None:
    """A stored video's (`zooctl.store.video_reader.StoredVideo`) check that its automatic masks
    hold an animal: the one `video add` made, else (a video stored before the check existed) made
    now from its frames, masks and segmenter report, as `video add` would have, and marked
    ``made_now``; None for a user's masks or a box's."""
    seg = rec.segmenter or {}
    if "animal_check" in seg or not is_checked(seg.get("name"), seg.get("box")):
        return seg.get("animal_check")
    return {**check_animal(rec.frames, rec.masks, seg), "made_now": True}


def is_checked(segmenter: str | None, box: Any) -> bool:
    """Whether masks made by ``segmenter`` (its name; "masks": the user's own) with ``box`` are
    checked: automatic masks made without a box (a box says where the animal is)."""
    return segmenter not in (None, "masks") and box is None
