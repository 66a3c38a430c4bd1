"""`video add` stores a segmenter's masks reading each frame once: a lazy view that upsamples a
frame when read (long clips, the edge-following upsample) is not upsampled twice."""

from __future__ import annotations

import numpy as np
import pytest
from test_video_store import _record

from zooctl.errors import InputError
from zooctl.store.videos import VideoStore
from zooctl.video.ingest import MIN_COVERAGE, store_masks
from zooctl.video.scratch import Resized


def _begin(store, rec):
    writer = VideoStore.open(store).begin_file("bg", rec.frames.shape[1:3][::-1])
    writer.add_frames(rec.frames)
    parts = (rec.flow_forward, rec.flow_backward, rec.occlusion_forward, rec.occlusion_backward)
    writer.add_flow(*parts)
    return writer


def test_a_segmenters_masks_are_read_once_specks_cleared_and_empty_frames_listed(store):
    rec = _record(h=80, w=112)
    t, h, w = rec.masks.shape
    small = rec.masks[:, ::2, ::2].copy()
    small[2] = False
    small[2, 5, 5] = True  # one pixel at half size: a speck under MIN_COVERAGE at full size
    small[4] = False
    reads: list[int] = []

    def upsample(i, m):
        reads.append(i)
        return np.kron(m, np.ones((2, 2), bool))

    lazy = Resized(small, w, h, upsample)
    assert 0 < lazy[2].mean() < MIN_COVERAGE
    reads.clear()
    writer = _begin(store, rec)
    try:
        report = store_masks(lazy, writer, "animalnet", user=False)
        assert reads == list(range(t))  # each frame upsampled once
        assert report["empty_frames"] == [2, 4]
        summary = writer.finish(
            "bg", rec.fps, rec.source, rec.source_indices, rec.segmenter, rec.flow_estimator
        )
        VideoStore.open(store).add_written("bg", writer, summary)
    finally:
        writer.discard()
    want = np.stack([np.kron(m, np.ones((2, 2), bool)) for m in small])
    want[2] = False
    got = VideoStore.open(store).get("bg")
    assert np.array_equal(got.masks, want) and got.masks[3].any()


def test_a_segmenter_that_found_no_animal_is_refused(store):
    rec = _record()
    writer = _begin(store, rec)
    try:
        with pytest.raises(InputError, match="found no animal in any of the 12 frames"):
            store_masks(np.zeros_like(rec.masks), writer, "animalnet", user=False)
    finally:
        writer.discard()
    assert "bg" not in VideoStore.open(store).names()
