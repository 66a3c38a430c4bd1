"""The `bank search --gallery` image: the query crops in the first row, then one row per top asset
with, under each query frame, the asset's rendered view nearest to it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..store import views_h5
from .query import QueryFrames
from .search import SearchResult

THUMB = 128


def gallery_image(bank, query: QueryFrames, result: SearchResult, thumb: int = THUMB) -> np.ndarray:
    """(H, W, 3) uint8 sheet; rows: query, then each match of ``result`` in rank order."""
    import cv2

    from ..render.preview import contact_sheet

    def small(im: np.ndarray) -> np.ndarray:
        return cv2.resize(im, (thumb, thumb), interpolation=cv2.INTER_AREA)

    K = len(query.images)
    images = [small(im) for im in query.images]
    labels = [f"query frame {int(f)}" for f in query.frames]
    for rank, m in enumerate(result.matches, 1):
        sv = views_h5.read_views(
            views_h5.views_path(bank.root, m.name), images=True, embedders=[], rows=np.array(m.frame_views)
        )
        for j in range(K):
            images.append(small(sv.images[j]))
            labels.append(f"#{rank} {m.name} ({m.score:.2f})" if j == 0 else f"view {m.frame_views[j]}")
    return contact_sheet(images, labels, columns=K)


def save_gallery(path: str | Path, bank, query: QueryFrames, result: SearchResult) -> Path:
    from ..render.preview import save_png

    return save_png(path, gallery_image(bank, query, result))
