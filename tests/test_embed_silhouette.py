"""The silhouette embedder: a texture-blind shape descriptor that orders shapes by overlap."""

from __future__ import annotations

import numpy as np
import pytest

from zooctl.embed.silhouette import SilhouetteEmbedder
from zooctl.errors import InputError, UsageError


def _ellipse(h: int, w: int, cy: float, cx: float, ry: float, rx: float) -> np.ndarray:
    y, x = np.mgrid[:h, :w]
    return ((y - cy) / ry) ** 2 + ((x - cx) / rx) ** 2 <= 1


def test_descriptor_shape_and_norm():
    e = SilhouetteEmbedder(grid=16)
    d = e.embed_batch(np.stack([_ellipse(64, 64, 32, 32, 10, 25), _ellipse(64, 64, 32, 32, 25, 25)]))
    assert d.shape == (2, 256) and e.dim == 256 and e.input_kind == "mask"
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1, atol=1e-5)


def test_similarity_falls_with_disagreement():
    e = SilhouetteEmbedder()
    base = _ellipse(96, 96, 48, 48, 20, 40)
    near = _ellipse(96, 96, 49, 47, 19, 40)  # one pixel off
    fatter = _ellipse(96, 96, 48, 48, 30, 40)
    other = _ellipse(96, 96, 48, 48, 40, 12)  # tall instead of long
    d = e.embed_batch(np.stack([base, near, fatter, other]))
    sims = d[1:] @ d[0]
    assert sims[0] > sims[1] > sims[2]
    assert sims[0] > 0.97


def test_resolution_does_not_matter():
    e = SilhouetteEmbedder()
    small = _ellipse(64, 64, 32, 32, 12, 28)
    large = _ellipse(256, 256, 128, 128, 48, 112)
    d = e.embed_batch(np.stack([small, large[::4, ::4]]))
    d2 = e.embed_batch(large[None])
    assert float(d[0] @ d2[0]) > 0.98


def test_bad_input():
    with pytest.raises(InputError):
        SilhouetteEmbedder().embed_batch(np.zeros((2, 3, 4, 5)))
    with pytest.raises(UsageError):
        SilhouetteEmbedder(grid=2)
