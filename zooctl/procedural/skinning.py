"""Smooth skinning weights for tube parts: blend the bones near each point of the centre line.

Every ring of a tube takes the weights of its centre-line point, so a joint bends the whole cross
section together (no pinching between the front and back of a limb), and the weights fall off
smoothly with the distance from each bone segment (a Gaussian of width ``falloff``), so a bend is
spread over the neighbourhood of a joint instead of creasing at one ring.
"""

from __future__ import annotations

import numpy as np

from ..asset import sparsify_weights


def point_segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distances (N, M) from points p (N, 3) to segments a (M, 3) -> b (M, 3)."""
    ab = b - a
    denom = np.maximum(np.sum(ab * ab, axis=1), 1e-18)
    t = np.clip(np.einsum("nmk,mk->nm", p[:, None, :] - a[None], ab) / denom, 0.0, 1.0)
    closest = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(p[:, None, :] - closest, axis=-1)


def chain_weights(
    line: np.ndarray,
    chain_pos: np.ndarray,
    tip: np.ndarray,
    anchor_pos: np.ndarray | None,
    falloff: float,
) -> np.ndarray:
    """Dense weights (N, C + 1) of centre-line points over the chain's bones and the anchor.

    line (N, 3); chain_pos (C, 3) joint positions, bone i runs from chain_pos[i] to chain_pos[i+1]
    (the last one to ``tip``); anchor_pos (3,) or None: the anchor joint is treated as a point bone
    at the start of the chain. Column C is the anchor (all zero without one). Rows sum to 1.
    """
    ends = np.concatenate([chain_pos[1:], tip[None]])
    d = point_segment_distance(line, chain_pos, ends)
    if anchor_pos is not None:
        da = np.linalg.norm(line - chain_pos[0], axis=1) + 0.5 * falloff
        d = np.concatenate([d, da[:, None]], axis=1)
    else:
        d = np.concatenate([d, np.full((len(line), 1), np.inf)], axis=1)
    # Subtract the nearest distance so the Gaussian never underflows far from all bones.
    d = d - d.min(axis=1, keepdims=True)
    w = np.exp(-((d / max(falloff, 1e-9)) ** 2))
    return w / w.sum(axis=1, keepdims=True)


def sparse(dense: np.ndarray, k: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Top-k sparse weights (V, k) joints and weights; see `zooctl.asset.sparsify_weights`."""
    return sparsify_weights(dense, k)
