"""Stretchable bones and linear blend skinning (CASA supplement D, after Jacobson & Sorkine 2011).

Bones. Bone k runs from its head ``c_k`` (the joint's bind position) to its tail ``d_k``:

- a joint with children: the head of its *main* child, the child whose subtree has the most
  joints (ties: the first), so a spine bone points up the spine and not into a leg;
- a leaf joint: the bone continues its parent's direction ``c_k - c_parent`` up to the farthest
  projection of the vertices it dominates (skin weight >= 0.5), or half its parent bone's length
  when it dominates none; a root without children gets ``d_k = c_k`` (it cannot stretch).

Stretch. With length scale ``b_k`` the stretch vector is ``s_k = (b_k - 1)(d_k - c_k)`` and a
bind-space point ``p`` moves with bone k to ``p + e_k(p) s_k`` where ``e_k(p)`` is the fraction of
the projection of ``p`` onto the segment, clamped to [0, 1]. The posed vertex is

    v_i = sum_k w_ik M_k (p_i + e_k(p_i) s_k),   M_k = G_k @ inverse_bind_k,

which for rigid ``M_k`` is exactly CASA's ``c_k^t + R_k^t (e_k(p_i) s_k + (p_i - c_k))``. The
skeleton moves consistently: a child joint's head is carried by its parent's stretch,
``o_j += L(inverse_bind_parent) e_parent(c_j) s_parent`` (``L``: the 3x3 part), which is the
parent's rest offset scaled by ``b_parent`` for the main child, so the mesh stays continuous at
every joint, branching ones included.

Weights stay on the simplex: each vertex keeps ``K`` candidate bones (its template bones, then the
nearest others) and its weights are a softmax over learnable logits.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

Tensor = torch.Tensor
DENSE_MAX_JOINTS = 256  # up to here skinning blends through dense (V, J) weights (see below)


def bone_segments(
    heads: np.ndarray, parents: np.ndarray, points: np.ndarray, dense_weights: np.ndarray
) -> np.ndarray:
    """(J, 3) bone tails ``d_k`` for heads (J, 3); see the module docstring for the rule.

    points (V, 3) bind vertices, dense_weights (V, J) skin weights (used for leaf lengths).
    """
    J = len(parents)
    subtree = np.ones(J, dtype=np.int64)
    for j in range(J - 1, 0, -1):
        if parents[j] >= 0:
            subtree[parents[j]] += subtree[j]
    main_child = np.full(J, -1, dtype=np.int64)
    for j in range(J):
        p = parents[j]
        if p >= 0 and (main_child[p] < 0 or subtree[j] > subtree[main_child[p]]):
            main_child[p] = j
    tails = heads.astype(np.float64).copy()
    for k in range(J):
        if main_child[k] >= 0:
            tails[k] = heads[main_child[k]]
    for k in range(J):
        p = parents[k]
        if main_child[k] >= 0 or p < 0:
            continue
        axis = heads[k] - heads[p]
        parent_len = float(np.linalg.norm(tails[p] - heads[p]))
        n = float(np.linalg.norm(axis))
        if n < 1e-9:
            continue
        axis = axis / n
        owned = dense_weights[:, k] >= 0.5
        length = float(((points[owned] - heads[k]) @ axis).max()) if owned.any() else 0.0
        if length <= 1e-9:
            length = 0.5 * parent_len
        tails[k] = heads[k] + axis * length
    return tails


def endpoint_weights(points: Tensor, heads: Tensor, tails: Tensor, eps: float = 1e-12) -> Tensor:
    """``e_k(p)``: the clamped fraction of the projection of p onto each bone segment.

    points (..., N, 3) and heads/tails (..., N, 3) (already gathered per point) -> (..., N) in [0, 1].
    A zero-length bone gives 0.
    """
    axis = tails - heads
    num = ((points - heads) * axis).sum(-1)
    den = (axis * axis).sum(-1)
    return (num / den.clamp_min(eps)).clamp(0.0, 1.0) * (den > eps)


def stretch_vectors(bone_scales: Tensor, heads: Tensor, tails: Tensor) -> Tensor:
    """``s_k = (b_k - 1)(d_k - c_k)``: bone_scales (..., J), heads/tails (J, 3) -> (..., J, 3)."""
    return (bone_scales - 1.0)[..., None] * (tails - heads)


def child_offset_shift(stretch: Tensor, parents: Tensor, child_e: Tensor, inverse_bind: Tensor) -> Tensor:
    """How much each joint's local translation moves when its parent bone stretches.

    stretch (..., J, 3) bind-space stretch vectors; parents (J,) long (roots -1); child_e (J,) the
    parent's endpoint weight at each joint's head; inverse_bind (J, 4, 4).
    Returns (..., J, 3) in each parent's joint frame (zero for roots).
    """
    has_parent = parents >= 0
    p = parents.clamp_min(0)
    lin = inverse_bind[p, :3, :3]  # (J, 3, 3)
    shift = torch.einsum("jab,...jb->...ja", lin, stretch.index_select(-2, p) * child_e[:, None])
    return shift * has_parent[:, None].to(shift.dtype)


def linear_blend_skinning(
    points: Tensor,
    mats: Tensor,
    bones: Tensor,
    weights: Tensor,
    stretch: Tensor | None = None,
    endpoint: Tensor | None = None,
) -> Tensor:
    """Posed vertices ``sum_k w_k M_k (p + e_k s_k)``.

    points (V, 3) or (..., V, 3) bind vertices; mats (..., J, 4, 4) skinning matrices
    ``G_k @ inverse_bind_k``; bones (V, K) long candidate bones; weights (V, K) or (..., V, K)
    on the simplex; stretch (..., J, 3) bind-space stretch vectors and endpoint (V, K) the
    ``e_k(p)`` of each candidate, both optional. Returns (..., V, 3).
    """
    A = mats[..., :3, :]  # (..., J, 3, 4): affine part only
    J = mats.shape[-3]
    if J <= DENSE_MAX_JOINTS and points.dim() == 2 and weights.dim() == 2 and _batch_holds(mats, stretch):
        return _shared_weights_skinning(points, A, bones, weights, stretch, endpoint)
    if J <= DENSE_MAX_JOINTS:
        # Scatter the K candidates into dense (V, J) weights and blend with one matmul: faster
        # forward + backward than gathering (V, K, 3, 4) matrices, whose backward is a scatter-add
        # (BENCHMARKS.md, "Measurements behind code choices").
        blended = (_dense_weights(weights, bones, J) @ A.flatten(-2)).unflatten(-1, (3, 4))  # (..., V, 3, 4)
    else:
        blended = torch.einsum("...vk,...vkij->...vij", weights, A[..., bones, :, :])
    out = (blended[..., :3] @ points[..., None]).squeeze(-1) + blended[..., 3]
    if stretch is not None:
        out = out + stretch_offsets(mats, bones, weights, stretch, endpoint)
    return out


def _batch_holds(mats: Tensor, stretch: Tensor | None) -> bool:
    """Whether the stretch vectors broadcast to the matrices' batch without widening it."""
    if stretch is None:
        return True
    batch = mats.shape[:-3]
    try:
        return torch.broadcast_shapes(stretch.shape[:-2], batch) == batch
    except RuntimeError:
        return False


def _dense_weights(weights: Tensor, bones: Tensor, num_joints: int) -> Tensor:
    """(..., V, J) dense weights from (..., V, K) candidate weights of the (V, K) ``bones``
    (repeated candidates add up)."""
    dense = weights.new_zeros(weights.shape[:-1] + (num_joints,))
    return dense.scatter_add(-1, bones.expand(weights.shape), weights)


def _shared_weights_skinning(
    points: Tensor, A: Tensor, bones: Tensor, weights: Tensor, stretch: Tensor | None, endpoint: Tensor | None
) -> Tensor:
    """`linear_blend_skinning` for points (V, 3) and weights (V, K) shared by every pose of the
    batch: all poses' matrices side by side in one (V, J) @ (J, 4 x poses x 3) product, its four
    column blocks (x, y, z, 1) weighted by each point's homogeneous coordinates. One large product
    instead of a batched one over broadcast copies of the weights, and no per-vertex 3x3 products.
    A (..., J, 3, 4) affine parts of the skinning matrices."""
    batch, J, V = A.shape[:-3], A.shape[-3], points.shape[0]
    A = A.reshape(-1, J, 3, 4)
    N = A.shape[0]
    cols = A.permute(1, 3, 0, 2).reshape(J, 4 * N * 3)  # column (c, n, i) = A[n, j, i, c]
    ph = torch.cat((points, points.new_ones(V, 1)), -1)  # (V, 4)
    out = ((_dense_weights(weights, bones, J) @ cols).view(V, 4, N * 3) * ph[:, :, None]).sum(1)
    if stretch is not None:
        s = stretch.expand(batch + stretch.shape[-2:]).reshape(N, J, 3)
        moved = (A[..., :3] @ s[..., None]).squeeze(-1)  # (N, J, 3): L_k s_k
        out = out + _dense_weights(weights * endpoint, bones, J) @ moved.transpose(0, 1).reshape(J, N * 3)
    # Contiguous once here, rather than copied by each kernel that reads the posed vertices.
    return out.view(V, N, 3).transpose(0, 1).contiguous().view(batch + (V, 3))


def stretch_offsets(
    mats: Tensor, bones: Tensor, weights: Tensor, stretch: Tensor, endpoint: Tensor
) -> Tensor:
    """The stretch part of skinning, ``sum_k w_k L_k e_k s_k`` (linear in the stretch vectors).

    mats (..., J, 4, 4), bones (V, K), weights (V, K) or (..., V, K), stretch (..., J, 3),
    endpoint (V, K) -> (..., V, 3).
    """
    A = mats[..., :3, :]
    J = mats.shape[-3]
    moved = (A[..., :3] @ stretch[..., None]).squeeze(-1)  # (..., J, 3): L_k s_k
    we = weights * endpoint
    if J <= DENSE_MAX_JOINTS:
        return _dense_weights(we, bones, J) @ moved
    return torch.einsum("...vk,...vkc->...vc", we, moved[..., bones, :])


def candidate_bones(
    dense_weights: np.ndarray, points: np.ndarray, heads: np.ndarray, tails: np.ndarray, k: int
) -> tuple[np.ndarray, np.ndarray]:
    """Each vertex's K candidate bones: its template bones by weight, then the nearest bone segments.

    dense_weights (V, J), points (V, 3), heads/tails (J, 3) -> bones (V, K) int64, weights (V, K)
    (the template weights of the candidates, rows summing to one).
    """
    V, J = dense_weights.shape
    k = min(k, J)
    axis = tails - heads
    den = np.maximum((axis * axis).sum(-1), 1e-12)
    rel = points[:, None, :] - heads[None]  # (V, J, 3)
    t = np.clip((rel * axis[None]).sum(-1) / den, 0.0, 1.0)
    dist = np.linalg.norm(rel - t[..., None] * axis[None], axis=-1)  # (V, J)
    # Weight first, distance breaks ties (and orders the zero-weight fill-ins).
    order = np.lexsort((dist, -dense_weights), axis=-1)[:, :k]
    w = np.take_along_axis(dense_weights, order, 1).clip(min=0)
    s = w.sum(1, keepdims=True)
    w = np.where(s > 0, w / np.where(s > 0, s, 1), np.eye(1, k, 0))
    return order.astype(np.int64), w


def seam_groups(points: np.ndarray, bones: np.ndarray, tol: float = 1e-6) -> np.ndarray:
    """(V,) int64 a group per vertex: vertices at one bind position (within ``tol`` of the mesh's
    size) with the same candidate bones (V, K) share a group, numbered in order of first vertex.

    Flat-shaded and UV-mapped meshes split the surface at every seam into copies of a vertex (the
    Quaternius animals: a copy per face, 3,966 vertices at 977 positions); skinning weights
    learned per copy pull the copies apart and open cracks between the faces (17-42 % of the
    edges of the fits measured: BENCHMARKS.md, "Shared seams and the edge-stretch term")."""
    size = float(np.ptp(points, axis=0).max()) if len(points) else 0.0
    cell = np.round(points / max(tol * size, 1e-30)).astype(np.int64)
    _, first, inverse = np.unique(
        np.concatenate([cell, bones], 1), axis=0, return_index=True, return_inverse=True
    )
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    return rank[inverse.reshape(-1)]


def mean_by_group(rows: Tensor, groups: Tensor, num_groups: int) -> Tensor:
    """(U, ...) the mean of ``rows`` (V, ...) over each group of ``groups`` (V,) in [0, U)."""
    total = rows.new_zeros((num_groups, *rows.shape[1:])).index_add_(0, groups, rows)
    count = torch.bincount(groups, minlength=num_groups).clamp(min=1).to(rows.dtype)
    return total / count.view(-1, *([1] * (rows.dim() - 1)))


class SkinWeights(nn.Module):
    """Learnable skinning weights on the simplex: softmax over each vertex's K candidate bones.

    bones: (V, K) candidate bones; init: (V, K) initial weights on the simplex; groups: (V,) which
    vertices share their weights (`seam_groups`; default: none). ``logits`` (U, K), a row per group;
    ``forward()`` -> (V, K) weights, rows summing to one.
    """

    def __init__(self, bones: Tensor, init: Tensor, floor: float = 1e-8, groups: Tensor | None = None):
        super().__init__()
        self.register_buffer("bones", bones.long())
        logits = torch.log(init.clamp_min(floor))
        V = len(logits)
        if groups is None:
            groups = torch.arange(V)
        self.register_buffer("groups", groups.long())
        self.shared = int(groups.max()) + 1 < V if V else False
        self.logits = nn.Parameter(
            mean_by_group(logits, self.groups, int(groups.max()) + 1) if self.shared else logits
        )
        self._register_load_state_dict_pre_hook(self._from_per_vertex)

    def as_groups(self, rows: Tensor) -> Tensor:
        """``rows`` (V, ...), a row per vertex, as (U, ...) a row per group (each group's mean);
        rows that are per group already are returned as they are."""
        if rows.shape[0] == len(self.groups) != self.logits.shape[0]:
            return mean_by_group(rows, self.groups.to(rows.device), self.logits.shape[0])
        return rows

    def _from_per_vertex(self, state, prefix, *args) -> None:
        """A state saved without shared seams (a logit row per vertex) loads as each group's
        mean; one saved before the groups buffer existed gets this model's."""
        key = prefix + "logits"
        if prefix + "groups" not in state:
            state[prefix + "groups"] = self.groups
        if key in state:
            state[key] = self.as_groups(state[key])

    def forward(self) -> Tensor:
        w = self.group_weights()
        return w[self.groups] if self.shared else w

    def group_weights(self) -> Tensor:
        """(U, K) the weights of each group (of each vertex where no seams are shared)."""
        return torch.softmax(self.logits, dim=-1)

    def dense(self, num_joints: int) -> Tensor:
        """(V, J) dense weights (for inspection and export)."""
        w = self()
        return w.new_zeros(w.shape[0], num_joints).scatter_add_(1, self.bones, w)
