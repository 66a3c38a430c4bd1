"""The fit's notes on its masks: frames without an animal, and an animal too small to shape."""

from __future__ import annotations

import numpy as np

from zooctl.fit.inputs import SMALL_ANIMAL_SIDE, mask_areas, mask_notes


def _masks(t: int, side: int, empty: tuple[int, ...] = ()) -> np.ndarray:
    m = np.zeros((t, 120, 160), bool)
    m[:, 10 : 10 + side, 20 : 20 + side] = True
    m[list(empty)] = False
    return m


def test_masks_of_a_whole_animal_in_every_frame_get_no_note():
    assert mask_notes(_masks(6, SMALL_ANIMAL_SIDE)) == []


def test_frames_without_an_animal_are_counted():
    (note,) = mask_notes(_masks(6, 60, empty=(1, 4)))
    assert "no animal on 2 of 6 frames" in note


def test_an_animal_under_the_square_is_too_small_to_shape():
    (note,) = mask_notes(_masks(6, SMALL_ANIMAL_SIDE - 1))
    assert f"a square of {SMALL_ANIMAL_SIDE - 1} px" in note
    # the mean is over the frames that hold the animal: empty frames do not make it small
    notes = mask_notes(_masks(6, 40, empty=(0, 1, 2, 3)))
    assert len(notes) == 1 and "no animal on 4 of 6" in notes[0]


def test_mask_areas_read_a_chunk_at_a_time_as_the_whole():
    m = _masks(70, 10, empty=(3,))  # more frames than one chunk
    a = mask_areas(m)
    assert a.shape == (70,) and a[3] == 0 and (np.delete(a, 3) == 100).all()
