"""Side-by-side preview frames: the video with its mask outline and box, and the colour-coded flow."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from .flow import flow_to_rgb

OUTLINE_RGB = (0, 255, 0)
BOX_RGB = (255, 200, 0)


def preview_frame(
    frame: np.ndarray,
    mask: np.ndarray,
    flow: np.ndarray,
    occlusion: np.ndarray | None,
    max_magnitude: float,
    label: str = "",
) -> np.ndarray:
    """(H, W, 3) frame, (H, W) mask, (H, W, 2) flow -> (H, 2W, 3) uint8: outline + box | flow colours.

    Occluded pixels (forward-backward check failed) are shown darkened in the flow half; ``label``
    (how the frame's mask was made) is written in its corner.
    """
    left = frame.copy()
    contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    thick = max(1, round(frame.shape[0] / 240))
    cv2.drawContours(left, contours, -1, OUTLINE_RGB, thick)
    if mask.any():
        x, y, w, h = cv2.boundingRect(mask.astype(np.uint8))
        cv2.rectangle(left, (x, y), (x + w - 1, y + h - 1), BOX_RGB, 1)
    if label:
        scale = frame.shape[0] / 480
        cv2.putText(
            left, label, (8, round(24 * scale)), cv2.FONT_HERSHEY_SIMPLEX, 0.7 * scale, BOX_RGB, thick
        )
    right = flow_to_rgb(flow, max_magnitude)
    if occlusion is not None:
        right[occlusion] = right[occlusion] // 3
    return np.concatenate([left, right], axis=1)


def write_preview(rec, out: str | Path, progress=None) -> Path:
    """Write a stored video's preview as H.264: ``rec`` a `zooctl.store.video_reader.StoredVideo`
    (read a frame at a time) or a `zooctl.store.videos.VideoRecord` with frames, masks and flow."""
    from ..io.video import write_mp4
    from .stats import magnitude_percentile

    t = len(rec.frames)
    p99, _ = magnitude_percentile(lambda: iter(rec.flow_forward), 0.99)
    scale = max(p99, 1.0)  # one scale for the whole clip, so colours compare
    how = (rec.segmenter or {}).get("seeding") or [""] * t

    def frames():
        for i in range(t):
            if i < t - 1:
                fl, occ = rec.flow_forward[i], rec.occlusion_forward[i]
            else:  # the last frame has no forward flow: show the backward one reversed
                fl, occ = -rec.flow_backward[i - 1], rec.occlusion_backward[i - 1]
            yield preview_frame(rec.frames[i], rec.masks[i], fl, occ, scale, f"{i} {how[i]}".strip())
            if progress:
                progress(i + 1, t)

    return write_mp4(out, frames(), fps=rec.fps)
