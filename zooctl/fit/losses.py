"""Every loss term of a fit, by the name it has in the loss history and in ``LossWeights``.

| term | function | weight (``weights.*``) |
|---|---|---|
| mask | `soft_iou_loss` | ``mask`` (lambda1) |
| contour | `contour_loss` | ``contour`` (``dt`` in older configs: still read, with a warning) |
| flow | `flow_loss` | ``flow`` (beta) |
| root_smooth | `root_smoothness` | ``root_smooth`` |
| scale | `scale_prior` | ``scale_prior`` |
| skin | `skin_prior` | ``skin_prior`` |
| displacement | `displacement_prior` | ``displacement`` |
| pose | `pose_prior` (``pose_prior.kind`` rest), `clip_pose_loss` (clips) or the motion prior's ``loss`` (motion; `zooctl.motion.fit_prior`) | ``pose_prior`` |
| limits | `joint_limit_loss` (the template clips' joint ranges, `zooctl.fit.pose_prior.clip_joint_limits`) | ``joint_limits`` |
| ground | `sinking_loss` + `foot_sliding_loss` in the root's frame (`body_frame`), the ground from `ground_height` | ``ground_contact`` |
| smooth_3d | `vertex_acceleration_loss` (the posed vertices in world space) | ``smooth_3d`` |
| edge_stretch | `edge_stretch_loss` (the posed surface's edges against the rest shape's, `mesh_edges`) | ``edge_stretch`` |
| gait | `gait_symmetry_loss` (mirrored joints' positions over the clip in the root's frame; the model's ``mirrored_joints``) | ``gait_symmetry`` |
| photo | `zooctl.fit.photometric.photometric_loss` (the surface in learned per-vertex colours against the frames) | ``photometric`` |
| smooth, symmetry, bone_length | the articulation model's ``smoothness_loss``, ``symmetry_loss``, ``bone_length_loss`` (CASA eq. 6, 7; `zooctl.rig.priors`, since they belong to the model) | ``smooth`` (lambda2), ``symmetry`` (lambda3), ``bone_length`` |

`zooctl.fit.stages.StageRunner.loss` weights and sums them; change a weight's default in
`zooctl.fit.config.LossWeights` (and its preset), or per run with a ``--config`` file.

Targets live at the fit resolution (h, w). ``MaskTargets`` precomputes, per frame, the coverage
(T, h, w) in [0, 1], the distance from every pixel to the mask (for vertices that fall outside
it) and a fixed sample of mask pixels (that some vertex should cover).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import torch
import torch.nn.functional as F

from ..errors import InputError
from ..render import _kernels
from ..rig.priors import reflect
from ..rig.rotations import quat_conjugate, quat_mul, quat_normalize, quat_to_axis_angle, quat_to_matrix

if TYPE_CHECKING:
    from .pose_prior import ClipPoseStats, JointLimits

Tensor = torch.Tensor


@dataclass
class MaskTargets:
    """coverage (T, h, w) float; outside_dt (T, 1, h, w) distance to the mask in pixels / max(h, w);
    samples (T, S, 2) mask pixel centres (x, y); sample_ok (T, S) bool; present (T,) bool (non-empty)."""

    coverage: Tensor
    outside_dt: Tensor
    samples: Tensor
    sample_ok: Tensor
    present: Tensor

    @classmethod
    def build(
        cls, coverage: np.ndarray, num_samples: int = 256, seed: int = 0, device: str = "cpu"
    ) -> MaskTargets:
        import cv2

        T, h, w = coverage.shape
        binary = coverage >= 0.5
        dt = np.zeros((T, h, w), np.float32)
        samples = np.zeros((T, num_samples, 2), np.float32)
        ok = np.zeros((T, num_samples), bool)
        rng = np.random.default_rng(seed)
        for t in range(T):
            if binary[t].any():
                dt[t] = cv2.distanceTransform((~binary[t]).astype(np.uint8), cv2.DIST_L2, 3)
                ys, xs = np.nonzero(binary[t])
                pick = rng.choice(len(xs), num_samples, replace=len(xs) < num_samples)
                samples[t] = np.stack((xs[pick] + 0.5, ys[pick] + 0.5), -1)
                ok[t] = True
        tt = lambda a, dt_=torch.float32: torch.as_tensor(a, dtype=dt_, device=device)  # noqa: E731
        return cls(
            tt(coverage),
            tt(dt / max(h, w))[:, None],
            tt(samples),
            tt(ok, torch.bool),
            tt(binary.reshape(T, -1).any(1), torch.bool),
        )


def soft_iou_loss(sil: Tensor, target: Tensor, weight: Tensor) -> Tensor:
    """1 - soft IoU per frame, averaged with ``weight`` (B,). sil, target: (B, h, w)."""
    inter = (sil * target).flatten(1).sum(1)
    union = (sil + target - sil * target).flatten(1).sum(1).clamp_min(1e-6)
    per = 1.0 - inter / union
    return (per * weight).sum() / weight.sum().clamp_min(1.0)


@torch.no_grad()
def nearest_points(queries: Tensor, points: Tensor) -> Tensor:
    """(B, S) long: the index of the point of points (B, V, 2) nearest to each of queries (B, S, 2),
    the first on ties. CPU float tensors use a C++ kernel (`zooctl.render._kernels`) that ranks by
    the squared distance itself; elsewhere (CUDA, no compiler) |x|^2 - 2 q.x, which ranks the
    same up to float rounding in near-ties."""
    q, p = queries.contiguous(), points.contiguous()
    kernel = _kernels.kernel_for("nearest_points", q, p)
    if kernel is not None and p.shape[1] < 2**24:  # the kernel carries indices as floats
        idx = torch.empty(q.shape[:2], dtype=torch.long)
        kernel(q, p, q.shape[0], q.shape[1], p.shape[1], idx)
        return idx
    # min(-1).indices gives argmin's first minimum, and is faster than argmin on the CPU.
    return (p.square().sum(-1)[:, None] - 2.0 * torch.bmm(q, p.transpose(1, 2))).min(-1).indices


def contour_loss(
    xy: Tensor, frames: Tensor, targets: MaskTargets, weight: Tensor, max_points: int = 1500
) -> Tensor:
    """Vertices outside their mask (distance-transform lookup) + mask pixels far from every vertex.

    xy (B, V, 2) projected vertices in fit pixels for the given frame indices (B,). Both halves are
    in units of the image size, squared. Gives long-range gradients where the soft silhouette has
    none (a template far from its mask), at a cost independent of the image size.
    """
    B, V, _ = xy.shape
    h, w = targets.coverage.shape[1:]
    if V > max_points:  # a fixed, even subsample keeps the cost flat for dense meshes
        xy = xy[:, :: int(np.ceil(V / max_points))]
    grid = torch.stack((xy[..., 0] / w * 2 - 1, xy[..., 1] / h * 2 - 1), -1)[:, None]  # (B, 1, V', 2)
    d_out = F.grid_sample(targets.outside_dt[frames], grid, align_corners=False, padding_mode="border")[
        :, 0, 0
    ]
    # Beyond the fit image the distance transform is clamped at its border (no gradient there), so
    # add how far a vertex lies outside it: parts sticking out of the crop are pulled back in.
    beyond = (
        (-xy[..., 0]).clamp_min(0)
        + (xy[..., 0] - w).clamp_min(0)
        + (-xy[..., 1]).clamp_min(0)
        + (xy[..., 1] - h).clamp_min(0)
    ) / max(h, w)
    outside = ((d_out + beyond) ** 2).mean(1)
    pts = targets.samples[frames]  # (B, S, 2)
    # The nearest vertex of each sample without autograd (the backward of a full cdist costs
    # more than the rest of a fit step), then the distance to it with autograd.
    nearest = nearest_points(pts, xy.detach())
    closest = xy.gather(1, nearest[..., None].expand(-1, -1, 2))  # (B, S, 2)
    near = (pts - closest).square().sum(-1).add(1e-12).sqrt() / max(h, w)  # (B, S)
    ok = targets.sample_ok[frames].to(near.dtype)
    cover = ((near**2) * ok).sum(1) / ok.sum(1).clamp_min(1.0)
    per = outside + cover
    return (per * weight).sum() / weight.sum().clamp_min(1.0)


def flow_loss(rendered: Tensor, rendered_mask: Tensor, observed: Tensor, valid: Tensor) -> Tensor:
    """Mean robust (Huber, 1 px) error between rendered and observed flow where both are valid.

    rendered, observed (B, h, w, 2) pixels; rendered_mask, valid (B, h, w) bool.
    """
    m = (rendered_mask & valid).to(rendered.dtype)
    err = F.smooth_l1_loss(rendered, observed, reduction="none", beta=1.0)  # (B, h, w, 2)
    # Both components weighted at once (no reduction over the last, 2-wide axis first).
    return (err * m[..., None]).sum() / m.sum().clamp_min(1.0)


def root_smoothness(root_rotation: Tensor, root_translation: Tensor, size: float) -> Tensor:
    """Accelerations of the root translation (over the template size) and root rotation changes."""
    T = root_translation.shape[0]
    if T < 2:
        return root_translation.sum() * 0.0
    q = root_rotation / root_rotation.norm(dim=-1, keepdim=True)
    rot = (1.0 - (q[1:] * q[:-1]).sum(-1) ** 2).mean()
    if T < 3:
        return rot
    acc = root_translation[2:] - 2 * root_translation[1:-1] + root_translation[:-2]
    return rot + (acc**2).sum(-1).mean() / size**2


def scale_prior(log_scale: Tensor) -> Tensor:
    """The log global scale near 0 (the template's size): ``log_scale**2``, a scalar."""
    return log_scale**2


def skin_prior(logits: Tensor, init_logits: Tensor) -> Tensor:
    """KL(template weights || current weights) per vertex, averaged; logits (V, K)."""
    cur = torch.log_softmax(logits, -1)
    init = torch.log_softmax(init_logits, -1)
    return (init.exp() * (init - cur)).sum(-1).mean()


def displacement_prior(disp: Tensor, size: float) -> Tensor:
    """Mean squared displacement (V, 3) relative to the template size squared."""
    return (disp**2).sum(-1).mean() / size**2


def pose_prior(rotations: Tensor, rest: Tensor) -> Tensor:
    """Joint rotations (T, J, 4) near the rest pose (J, 4): mean of ``1 - <q, q_rest>^2``."""
    q = rotations / rotations.norm(dim=-1, keepdim=True)
    return (1.0 - (q * rest).sum(-1) ** 2).mean()


def rest_relative_vectors(rotations: Tensor, rest: Tensor) -> Tensor:
    """(T, J, 3) rotation vectors of rest^-1 q for rotations (T, J, 4) (normalised here), rest (J, 4):
    what the clip statistics and the joint limits are learned on."""
    return quat_to_axis_angle(quat_mul(quat_conjugate(rest)[None], quat_normalize(rotations)))


def clip_pose_loss(rotations: Tensor, rest: Tensor, stats: ClipPoseStats) -> Tensor:
    """Mean squared Mahalanobis distance per degree of freedom of rotations (T, J, 4) from the
    clips' per-joint Gaussian (rest (J, 4) the rest rotations)."""
    d = rest_relative_vectors(rotations, rest) - stats.mean  # (T, J, 3)
    return torch.einsum("tja,jab,tjb->tj", d, stats.precision, d).mean() / 3.0


def joint_limit_loss(rotations: Tensor, rest: Tensor, limits: JointLimits) -> Tensor:
    """Squared excess (radians^2) of rest^-1 q's rotation vector beyond each joint's range, summed
    over joints and axes, mean over frames; rotations (T, J, 4), rest (J, 4). Zero inside."""
    v = rest_relative_vectors(rotations, rest)
    excess = torch.relu(limits.low - v) + torch.relu(v - limits.high)
    return (excess**2).sum((1, 2)).mean()


# -- ground contact and 3D smoothness --------------------------------------------------------
# The fit has no world but the camera's: the root transform absorbs the camera's motion, so the
# ground is a plane of the root's frame, normal to the template's up axis (Y). A planted foot
# holds still in that frame when the animal stands in place (as the benchmark's do while the
# camera orbits them); a walking animal's stance foot moves back in it, which the sliding term
# pays for.
UP_AXIS = 1
CONTACT_BAND = 0.02  # of the body size: vertices this close above the ground touch it


def body_frame(verts: Tensor, root_rotation: Tensor, root_translation: Tensor) -> Tensor:
    """(B, V, 3) world vertices ``verts`` in their frame's root frame: ``R^T (v - t)`` for
    root_rotation (B, 4) wxyz and root_translation (B, 3)."""
    R = quat_to_matrix(root_rotation)  # (B, 3, 3); row vectors: (R^T x)^T = x^T R
    return (verts - root_translation[:, None, :]) @ R


def lowest_heights(body: Tensor) -> Tensor:
    """(B,) each frame's lowest height along the up axis; body (B, V, 3) in the root frame."""
    return body[..., UP_AXIS].min(-1).values


def ground_height(lowest: Tensor) -> Tensor:
    """() the ground's height from each frame's lowest height (T,): their median, so the frames
    whose body dips below where it usually stands sink and the ones lifted (a jump) do not count."""
    return lowest.median()


def sinking_loss(body: Tensor, ground: Tensor | float, size: Tensor | float) -> Tensor:
    """Mean squared depth of the vertices below the ground, relative to ``size`` squared; body
    (B, V, 3) in the root frame, ground its height. Zero when nothing is below it."""
    depth = torch.relu(ground - body[..., UP_AXIS]) / size  # (B, V)
    below = (depth > 0).to(depth.dtype)
    return (depth**2).sum() / below.sum().clamp_min(1.0)


def foot_sliding_loss(
    body: Tensor, ground: Tensor | float, size: Tensor | float, band: float = CONTACT_BAND
) -> Tensor:
    """Mean squared motion along the ground, relative to ``size`` squared, of the vertices touching
    it in two consecutive frames of body (B, V, 3) (root frame, frames in order). A vertex's
    contact weight is 1 on (or below) the ground falling to 0 at ``band`` x ``size`` above it,
    the product of its two frames' and not differentiated: the term moves a foot along the ground,
    not off it."""
    if body.shape[0] < 2:
        return body.sum() * 0.0
    with torch.no_grad():
        above = (body[..., UP_AXIS] - ground).clamp_min(0.0) / (band * size)
        touch = (1.0 - above).clamp_min(0.0)  # (B, V)
        weight = touch[1:] * touch[:-1]
    step = body[1:] - body[:-1]  # (B-1, V, 3)
    along = step.square().sum(-1) - step[..., UP_AXIS].square()  # motion within the ground plane
    return (along * weight).sum() / weight.sum().clamp_min(1e-6) / size**2


def vertex_acceleration_loss(verts: Tensor, size: Tensor | float) -> Tensor:
    """Mean squared second difference over consecutive frames of verts (B, V, 3) (frames in
    order, world space), relative to ``size`` squared: 3D temporal smoothness of the whole
    surface, root and joints together. Zero under three frames."""
    if verts.shape[0] < 3:
        return verts.sum() * 0.0
    acc = verts[2:] - 2.0 * verts[1:-1] + verts[:-2]
    return acc.square().sum(-1).mean() / size**2


def mesh_edges(faces: Tensor) -> Tensor:
    """(E, 2) the unique undirected edges of triangles ``faces`` (F, 3), lower index first."""
    e = torch.cat((faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]))
    return torch.unique(torch.sort(e, dim=1).values, dim=0)


class _EdgeSquaredLengthKernel(torch.autograd.Function):
    """CPU kernel of `edge_squared_length`: v (B, V, 3), edges (E, 2) -> (B, E)."""

    @staticmethod
    def forward(ctx, v: Tensor, edges: Tensor) -> Tensor:  # type: ignore[override]
        v = v.detach().contiguous()
        B, V, _ = v.shape
        out = v.new_empty(B, edges.shape[0])
        _kernels.kernel_for("edge_sq_forward", v)(v, edges, B, V, edges.shape[0], out)
        ctx.save_for_backward(v, edges)
        return out

    @staticmethod
    def backward(ctx, g: Tensor):  # type: ignore[override]
        v, edges = ctx.saved_tensors
        B, V, _ = v.shape
        g_v = torch.empty_like(v)
        g = g.to(v.dtype).contiguous()
        _kernels.kernel_for("edge_sq_backward", v)(v, edges, g, B, V, edges.shape[0], g_v)
        return g_v, None


def edge_squared_length(verts: Tensor, edges: Tensor) -> Tensor:
    """(..., E) each edge's squared length in ``verts`` (..., V, 3), at least 1e-18: no square
    root, and a gradient finite at 0. CPU float tensors use a C++ kernel (`zooctl.render._kernels`):
    the gathers' backward costs more than the rest of the term on the CPU (BENCHMARKS.md)."""
    e = edges.contiguous()
    flat = verts.reshape(-1, *verts.shape[-2:])
    if _kernels.kernel_for("edge_sq_forward", flat, indices=(e,)) is not None and flat.shape[-1] == 3:
        if e.numel() and (int(e.min()) < 0 or int(e.max()) >= flat.shape[1]):
            raise InputError(f"edges name vertex {int(e.max())} but there are {flat.shape[1]} vertices")
        return _EdgeSquaredLengthKernel.apply(flat, e).view(*verts.shape[:-2], e.shape[0])
    d = verts.index_select(-2, e[:, 0]) - verts.index_select(-2, e[:, 1])
    return (d * d).sum(-1).clamp(min=1e-18)


def edge_log_stretch(verts: Tensor, rest: Tensor, edges: Tensor) -> Tensor:
    """(..., E) log of each edge's length in ``verts`` (..., V, 3) over its length in ``rest``
    (V, 3): 0 where articulation kept the surface's metric, log 2 where it doubled an edge."""
    return 0.5 * torch.log(edge_squared_length(verts, edges) / edge_squared_length(rest, edges))


def edge_stretch_loss(verts: Tensor, rest: Tensor, edges: Tensor, free: float = math.log(1.5)) -> Tensor:
    """Mean over the edges and frames of how far each posed edge of ``verts`` (B, V, 3) is
    stretched or squeezed beyond ``free`` (a log ratio) against the ``rest`` shape (V, 3) at the
    same global scale, squared. A surface torn by its skinning (neighbouring vertices following
    different bones) has edges at several times their length; bending at a joint, as artists'
    own clips do, stays within 1.5 times (their 99th percentile: 1.05-1.6 times, BENCHMARKS.md)."""
    excess = (edge_log_stretch(verts, rest, edges).abs() - free).clamp(min=0.0)
    return excess.square().mean()


def gait_symmetry_loss(
    joints: Tensor, pairs: Tensor, normal: Tensor, offset: Tensor | float, size: Tensor | float
) -> Tensor:
    """Left/right symmetry of a clip's motion. joints (T, J, 3): every frame's joints in the root
    frame (`body_frame`); pairs (P, 2) the joints (left, right) that mirror each other through the
    plane ``normal . x = offset`` (the model's ``mirrored_joints``).

    A walking or trotting animal's left and right legs pass through the same positions half a
    cycle apart, so over the clip each mirrored pair has the same mean position and the same
    spread; a fit that keeps the leg nearer the camera in front on every frame breaks both. The
    squared gaps of the two (the left joint reflected), relative to ``size``, averaged over the
    pairs. 0 without pairs or with fewer than two frames."""
    if len(pairs) == 0 or joints.shape[0] < 2:
        return joints.sum() * 0.0
    left = reflect(joints[:, pairs[:, 0]], normal, offset) / size  # (T, P, 3)
    right = joints[:, pairs[:, 1]] / size

    def spread(x: Tensor) -> Tensor:  # the standard deviation, with a finite gradient at rest
        return (x.var(0, correction=0) + 1e-8).sqrt()

    gap = (left.mean(0) - right.mean(0)).square() + (spread(left) - spread(right)).square()
    return gap.sum(-1).mean()
