"""How good masks are against ground truth, and choosing a setting without fitting it to the test.

J is DAVIS's region similarity: per frame |mask & truth| / |mask | truth|, a frame where both are
empty counting 1 (the animal is absent and nothing was masked), averaged over the frames.

`leave_one_out` picks a setting (a threshold, a weight) from scores measured per video: for each
video the setting is the one with the best mean J over the *other* videos, and that video's J at
it is what is reported, so no video's number comes from a choice that saw it.
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np


def frame_j(mask: np.ndarray, truth: np.ndarray) -> float:
    """Region IoU of two (H, W) bool masks; 1.0 when both are empty."""
    mask, truth = np.asarray(mask, bool), np.asarray(truth, bool)
    if mask.shape != truth.shape:
        raise ValueError(f"mask {mask.shape} and truth {truth.shape} differ in shape")
    union = int(np.count_nonzero(mask | truth))
    if union == 0:
        return 1.0
    return int(np.count_nonzero(mask & truth)) / union


def per_frame_j(masks, truth) -> np.ndarray:
    """(T,) float64 J of each frame of (T, H, W) masks against (T, H, W) truth."""
    if len(masks) != len(truth):
        raise ValueError(f"{len(masks)} masks for {len(truth)} ground-truth frames")
    return np.array([frame_j(m, g) for m, g in zip(masks, truth)], np.float64)


@dataclass
class LeaveOneOut:
    """A setting chosen leave-one-video-out.

    ``picked``: per video, the setting chosen on the other videos; ``held_out``: that video's J at
    it; ``best``: the setting with the best mean over all videos (in-sample), ``in_sample``: each
    video's J at ``best``.
    """

    picked: dict[str, Hashable]
    held_out: dict[str, float]
    best: Hashable
    in_sample: dict[str, float]

    @property
    def held_out_mean(self) -> float:
        return float(np.mean(list(self.held_out.values())))

    @property
    def in_sample_mean(self) -> float:
        return float(np.mean(list(self.in_sample.values())))


def best_setting(
    scores: Mapping[Hashable, Mapping[str, float]], videos: Sequence[str], prefer: Hashable | None = None
) -> Hashable:
    """The setting with the highest mean J over ``videos``. Ties (within 1e-9) go to ``prefer``
    (the default: a change must earn its place), else to the setting listed first."""
    if not videos:
        raise ValueError("no videos to choose a setting on")
    means = {s: float(np.mean([per[v] for v in videos])) for s, per in scores.items()}
    top = max(means.values())
    if prefer in means and means[prefer] >= top - 1e-9:
        return prefer
    return next(s for s, m in means.items() if m >= top - 1e-9)


def leave_one_out(
    scores: Mapping[Hashable, Mapping[str, float]], prefer: Hashable | None = None
) -> LeaveOneOut:
    """``scores[setting][video]``: J of each video at each setting (every setting scored on the
    same videos, at least two)."""
    if not scores:
        raise ValueError("no settings to choose from")
    videos = list(next(iter(scores.values())))
    for s, per in scores.items():
        if set(per) != set(videos):
            raise ValueError(f"setting {s!r} is scored on other videos than the first")
    if len(videos) < 2:
        raise ValueError("leave-one-out needs at least two videos")
    picked = {v: best_setting(scores, [o for o in videos if o != v], prefer) for v in videos}
    best = best_setting(scores, videos, prefer)
    return LeaveOneOut(
        picked=picked,
        held_out={v: float(scores[picked[v]][v]) for v in videos},
        best=best,
        in_sample={v: float(scores[best][v]) for v in videos},
    )
