"""Choosing the template: the bank asset named by ``--template``, else template retrieval.

Retrieval is `zooctl.retrieval` (CASA's embedding search over rendered views of every bank asset):
the masked crops of a few frames are embedded with the enabled embedders and the bank ranked.
`try_candidates` then gives the best few a short fit each and keeps the one whose silhouettes fit
the video best (``FitConfig.trials``): the embeddings rank body plans right about 7 times in 10
(BENCHMARKS.md, Retrieval), the fit's own mask IoU is a direct check.
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


def try_candidates(
    bank: Any,
    video: Any,
    candidates: list[dict[str, Any]],
    cfg: Any,
    reporter: Any = None,
) -> tuple[RiggedAsset, list[dict[str, Any]]]:
    """Short-fit the first ``cfg.trials.candidates`` retrieval candidates; (best template, the
    candidates with ``trial_iou`` added to those tried). Ties keep the retrieval order."""
    import copy

    from .run import fit_video

    tried = candidates[: cfg.trials.candidates]
    if len(tried) < 2:
        return bank.get(candidates[0]["name"]), candidates
    short = copy.deepcopy(cfg)
    short.trials.candidates = 1
    short.stage2.iters = cfg.trials.iters
    best, best_iou = None, -1.0
    for i, cand in enumerate(tried):
        if reporter is not None:
            reporter.message(f"trial fit {i + 1}/{len(tried)}: template {cand['name']}")
        asset = bank.get(cand["name"])
        iou = float(np.mean(fit_video(video, asset, short, reporter).iou))
        cand["trial_iou"] = round(iou, 4)
        if iou > best_iou:
            best, best_iou = asset, iou
    if reporter is not None:
        reporter.message(f"template {best.name}: trial mask IoU {best_iou:.3f}")
    return best, candidates
