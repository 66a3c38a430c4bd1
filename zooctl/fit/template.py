"""Choosing the template: the bank asset named by ``--template``, else template retrieval.

Retrieval is `zooctl.retrieval` (CASA's embedding search over rendered views of every bank asset):
the masked crops of a few frames are embedded with the enabled embedders and the bank ranked.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..asset import RiggedAsset
from ..errors import UsageError


def retrieve(
    bank: Any,
    frames: np.ndarray,
    masks: np.ndarray,
    exclude: set[str] | None = None,
    top: int = 5,
    device: str = "cpu",
) -> list[dict[str, Any]]:
    """Ranked candidates ``[{"name", "score", "distances"}]`` (best first, lower score is better)."""
    try:
        from ..retrieval.index import enabled_embedders
        from ..retrieval.query import QueryFrames, crops_from_frames
        from ..retrieval.search import embed_query, score_bank
    except ImportError as exc:  # pragma: no cover - retrieval ships with zooctl
        raise UsageError(
            "template retrieval is not available in this installation", hint="pass --template NAME"
        ) from exc
    images, crop_masks, chosen = crops_from_frames(frames, masks, 8, 224)
    query = QueryFrames(images, crop_masks, chosen, "fit")
    emb, _ = embed_query(query, enabled_embedders(), device)
    res = score_bank(bank, emb, exclude=exclude)
    if not res.matches:
        raise UsageError(
            "template retrieval found no candidate in the bank",
            hint="seed or fill the bank (`zooctl bank seed`, `zooctl bank add`), run `zooctl bank reindex`, or pass --template NAME",
        )
    return [
        {"name": m.name, "score": float(m.score), "distances": {k: float(v) for k, v in m.distances.items()}}
        for m in res.matches[:top]
    ]


def choose_template(
    bank: Any,
    name: str | None,
    frames: np.ndarray,
    masks: np.ndarray,
    exclude: set[str] | None = None,
    device: str = "cpu",
) -> tuple[RiggedAsset, list[dict[str, Any]]]:
    """(template asset, retrieval candidates) - candidates are empty when ``name`` was given."""
    if name is not None:
        return bank.get(name), []
    if len(bank) == 0:
        raise UsageError(
            "the bank is empty: there is no template to fit",
            hint="run `zooctl bank seed`, or add assets with `zooctl bank add`",
        )
    cands = retrieve(bank, frames, masks, exclude=exclude, device=device)
    return bank.get(cands[0]["name"]), cands
