"""The two optimisation stages of CASA section 3.4.

Stage 1 (global placement): the global scale u, the per-frame root rotation and translation and,
unless it was given, the focal length, on the mask terms only (soft-silhouette IoU plus the
contour distance term) with root smoothness and a weak scale prior.

Stage 2 (articulation): jointly the bone length scales, per-frame joint quaternions, root
transforms, the displacement MLP and the skinning weights, minimising

    lambda1 E_cue + lambda2 E_smooth + lambda3 E_symm + regularisers,
    E_cue = E_mask + beta E_flow,

with regularisers (every term in `zooctl.fit.losses`, weights in `zooctl.fit.config.LossWeights`): the contour term, root
smoothness, bone lengths near the template's and left/right equal, skinning weights near the
template's (KL), small displacements, joint rotations near the rest pose and the global scale
near the template's; off by default, ground contact and the posed vertices' 3D acceleration
(`zooctl.fit.losses`). Each step sees a contiguous window of ``batch`` frames (so flow has its
frame pairs); smoothness always covers the whole sequence (it is cheap: no rendering).
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from ..geometry import silhouette_iou
from ..render.base import check_silhouette, get_renderer
from ..render.windows import PairBudget
from .config import FitConfig, LossWeights, StageConfig
from .losses import (
    MaskTargets,
    body_frame,
    clip_pose_loss,
    contour_loss,
    displacement_prior,
    edge_stretch_loss,
    flow_loss,
    foot_sliding_loss,
    gait_symmetry_loss,
    ground_height,
    joint_limit_loss,
    lowest_heights,
    mesh_edges,
    pose_prior,
    root_smoothness,
    scale_prior,
    sinking_loss,
    skin_prior,
    soft_iou_loss,
    vertex_acceleration_loss,
)
from .photometric import initial_colours, photometric_loss
from .scene import FitScene

Tensor = torch.Tensor


@dataclass
class Targets:
    """What the losses compare against, at the fit resolution (see `MaskTargets`).

    flow (T-1, h, w, 2) observed forward flow in fit pixels and flow_valid (T-1, h, w) bool, or None;
    colours (T, h, w, 3) the frames in sRGB [0, 1] (`zooctl.fit.photometric.colour_targets`), or
    None: only the photometric term reads them.
    """

    masks: MaskTargets
    flow: Tensor | None = None
    flow_valid: Tensor | None = None
    colours: Tensor | None = None


def stage_config(cfg: FitConfig, stage: int, num_frames: int | None = None) -> StageConfig:
    """The stage's settings, its iterations for a clip of ``num_frames`` (`FitConfig.stage`)."""
    return cfg.stage(stage, num_frames)


def make_optimizer(
    scene: FitScene, cfg: FitConfig, stage: int, learn_focal: bool, shared: bool = True
) -> torch.optim.Adam:
    """Adam (0.9, 0.999) over the stage's parameters with CASA's learning-rate split; without
    ``shared``, only the per-frame ones (a later window of a long clip: the body is held)."""
    st = stage_config(cfg, stage)
    groups = [{"params": [scene.root_rotation, scene.root_translation], "lr": st.lr}]
    if stage == 2:
        groups.append({"params": [scene.rotations], "lr": st.lr if st.lr_joints is None else st.lr_joints})
    if not shared:
        return torch.optim.Adam(groups, betas=(0.9, 0.999), foreach=True)
    if stage == 1:
        groups.append({"params": [scene.model.log_scale], "lr": st.lr_shape})
        if learn_focal:
            groups.append({"params": [scene.log_focal], "lr": st.lr_shape * 0.2})
    else:
        if cfg.ablation.learn_skinning:
            groups.append({"params": [scene.model.skin.logits], "lr": st.lr * 5})
        groups.append({"params": scene.shape_parameters(), "lr": st.lr_shape})
    return torch.optim.Adam(groups, betas=(0.9, 0.999), foreach=True)


def smooth_weight(w: LossWeights, it: int, iters: int) -> float:
    """Stage 2's smoothness weight at iteration ``it`` of ``iters``: ``smooth_start`` decaying
    geometrically to ``smooth`` by ``smooth_until`` x ``iters``, then ``smooth``; ``smooth``
    throughout when ``smooth_start`` is 0 (or ``smooth`` is 0, which a geometric path cannot reach)."""
    if w.smooth_start <= 0 or w.smooth <= 0:
        return w.smooth
    a = min(1.0, it / max(w.smooth_until * iters, 1.0))
    return w.smooth_start ** (1.0 - a) * w.smooth**a


class StageRunner:
    """Runs one stage's steps; ``step(it)`` returns that step's loss terms.

    ``span`` (start, end): the frames it fits (default all). Frames before it are held; the one
    just before it joins its steps (flow and contact with what was fitted) and the two before it
    its sequence terms, so a window continues the motion it follows."""

    def __init__(
        self,
        scene: FitScene,
        targets: Targets,
        cfg: FitConfig,
        stage: int,
        span: tuple[int, int] | None = None,
        colours: Tensor | None = None,
    ):
        self.scene, self.targets, self.cfg, self.stage = scene, targets, cfg, stage
        self.lo, self.hi = span or (0, scene.num_frames)
        self.st = stage_config(cfg, stage, self.hi - self.lo)
        # Terms over the whole sequence are means over its frames, so each frame's share would
        # shrink as a clip grows while a step's data terms (a window) do not: past
        # schedule_frames they are scaled up, holding each frame as firmly as in a clip that long.
        T, ref = self.hi - self.lo, cfg.schedule_frames
        self.sequence_scale = max(1.0, T / ref) if ref > 0 else 1.0
        self.steps_from = max(self.lo - 1, 0)  # the first frame a step's window may hold
        self.sequence_from = max(self.lo - 2, 0)
        size = (scene.height, scene.width)
        # Renderers come from the registry (plugins included); soft_sigma is the soft renderer's.
        options = {"sigma": cfg.soft_sigma} if self.st.renderer == "soft" else {}
        self.silhouette = get_renderer(self.st.renderer, size, device=cfg.device, **options)
        self.flow_renderer = get_renderer("flow", size, device=cfg.device)
        # the renderers' pair budgets (`PairBudget`; plugins' renderers need not have one)
        self.budgets = [
            b
            for b in (getattr(r, "budget", None) for r in (self.silhouette, self.flow_renderer))
            if isinstance(b, PairBudget)
        ]
        for b in self.budgets:
            b.on = cfg.pair_budget
        self.gen = np.random.default_rng([cfg.seed, stage])
        present = targets.masks.present.cpu().numpy()
        self.present_idx = np.nonzero(present[: self.hi])[0]
        self.present_idx = self.present_idx[self.present_idx >= self.steps_from]
        self._queue: list[int] = []
        self.edges: Tensor | None = None  # the mesh's edges, once a term needs them
        # Each frame's lowest height in the root frame, refreshed from every step's window (no
        # extra posing): the ground is their median over the frames (`ground_height`).
        # Likewise every frame's joints in the root frame, for the gait term's clip statistics.
        w = cfg.weights
        ground = stage == 2 and w.ground_contact > 0
        gait = stage == 2 and w.gait_symmetry > 0 and hasattr(scene.model, "mirrored_joints")
        low, joints = self._root_frame_buffers() if ground or gait else (None, None)
        self.lowest = low if ground else None
        self.joints = joints if gait else None
        # The photometric term's per-vertex colours: a parameter of this stage only, ``colours``
        # (a paused fit's, as it left them) or started from the frames as the surface is posed now.
        self.colours: nn.Parameter | None = None
        if stage == 2 and w.photometric > 0 and targets.colours is not None:
            if colours is None:
                cover = targets.masks.coverage
                colours = initial_colours(scene, targets.colours, cover, range(self.steps_from, self.hi))
            self.colours = nn.Parameter(colours.detach().clone())

    @torch.no_grad()
    def _root_frame_buffers(self, batch: int = 16) -> tuple[Tensor, Tensor]:
        """(hi - sequence_from,) every frame's lowest height and (hi - sequence_from, J, 3) its
        joints, in its root frame, as posed now."""
        sc, low, joints = self.scene, [], []
        for s in range(self.sequence_from, self.hi, batch):
            idx = torch.arange(s, min(s + batch, self.hi), device=sc.rotations.device)
            p = sc.pose(idx)
            R, t = sc.root_rotation[idx], sc.root_translation[idx]
            low.append(lowest_heights(body_frame(p.vertices, R, t)))
            joints.append(body_frame(p.joints, R, t))
        return torch.cat(low), torch.cat(joints)

    def window(self) -> Tensor:
        """Stage 1: up to ``batch`` frames spread over the video (random offset). Stage 2: the next
        contiguous window of ``batch`` frames of this epoch (see `_epoch_windows`)."""
        lo = self.lo if self.stage == 1 else self.steps_from
        T = self.hi - lo
        B = min(self.st.batch, T)
        if self.stage == 1:
            offset = self.gen.uniform(0, T / B)
            idx = np.unique(np.minimum((offset + np.arange(B) * T / B).astype(int), T - 1))
            return torch.as_tensor(lo + idx, device=self.scene.rotations.device)
        if not self._queue:
            self._queue = self._epoch_windows(T, B)
        start = lo + self._queue.pop()
        return torch.arange(start, start + B, device=self.scene.rotations.device)

    def _epoch_windows(self, T: int, B: int) -> list[int]:
        """Window starts that tile the video once from a random offset, in random order, so every
        frame (the first and last ones too) gets the same number of updates; windows without any
        non-empty mask are left out."""
        offset = int(self.gen.integers(B)) if T > B else 0
        starts = sorted({int(np.clip(s, 0, T - B)) for s in range(offset - B, T, B) if s + B > 0})
        present = np.zeros(T, bool)
        present[self.present_idx - self.steps_from] = True
        starts = [s for s in starts if present[s : s + B].any()] or [0]
        return [starts[i] for i in self.gen.permutation(len(starts))]

    def loss(self, frames: Tensor, it: int = 0) -> tuple[Tensor, dict[str, float]]:
        """The stage's loss on ``frames`` at its iteration ``it`` (the smoothness schedule's), and
        its weighted terms as numbers."""
        total, terms = self.loss_terms(frames, it)
        return total, {k: float(v.detach()) for k, v in terms.items()}

    def loss_terms(self, frames: Tensor, it: int = 0) -> tuple[Tensor, dict[str, Tensor]]:
        """`loss` with the terms left as 0-d tensors on the fit's device (no host sync)."""
        share = getattr(self.scene.model, "shared_displacement", None)  # optional (`zooctl.rig.base`)
        with share() if share is not None else contextlib.nullcontext():
            return self._loss(frames, it)

    def _loss(self, frames: Tensor, it: int) -> tuple[Tensor, dict[str, Tensor]]:
        scene, w, ab = self.scene, self.cfg.weights, self.cfg.ablation
        tg = self.targets
        rest = None  # the rest shape as it is now: the edge-stretch term's reference
        if self.stage == 1:
            posed = None
        elif w.edge_stretch > 0:
            posed, rest = scene.pose_with_rest(frames)
        else:
            posed = scene.pose(frames)
        verts = scene.pose_rigid(frames) if posed is None else posed.vertices
        cam = scene.camera(len(frames))
        weight = tg.masks.present[frames].to(verts.dtype)
        terms: dict[str, Tensor] = {}
        sil = check_silhouette(
            self.st.renderer, self.silhouette(verts, scene.faces, cam), len(frames), scene.height, scene.width
        )
        terms["mask"] = w.mask * soft_iou_loss(sil, tg.masks.coverage[frames], weight)
        xy, _ = cam.project(verts)
        terms["contour"] = w.contour * contour_loss(xy, frames, tg.masks, weight)
        terms["root_smooth"] = (
            self.sequence_scale
            * w.root_smooth
            * root_smoothness(
                scene.root_rotation[self.sequence_from : self.hi],
                scene.root_translation[self.sequence_from : self.hi],
                scene.size,
            )
        )
        terms["scale"] = w.scale_prior * scale_prior(scene.model.log_scale)
        if self.stage == 2:
            if ab.flow and tg.flow is not None and len(frames) > 1 and w.flow > 0:
                out = self.flow_renderer(verts[:-1], scene.faces, scene.camera(len(frames) - 1), verts[1:])
                pairs = frames[:-1]
                both = weight[:-1] * weight[1:]
                valid = tg.flow_valid[pairs] & (tg.masks.coverage[pairs] > 0.5) & (both[:, None, None] > 0)
                terms["flow"] = w.flow * flow_loss(out["flow"], out["mask"], tg.flow[pairs], valid)
            smooth = smooth_weight(w, it, self.st.iters)
            if ab.smoothness and smooth > 0:
                q = scene.rotations[self.sequence_from : self.hi]
                q_all = q / q.norm(dim=-1, keepdim=True)
                terms["smooth"] = self.sequence_scale * smooth * scene.model.smoothness_loss(q_all)
            if ab.symmetry and w.symmetry > 0:
                terms["symmetry"] = w.symmetry * scene.model.symmetry_loss(sample=400) / scene.size**2
            if ab.stretch:
                terms["bone_length"] = w.bone_length * scene.model.bone_length_loss()
            if ab.learn_skinning:
                terms["skin"] = w.skin_prior * skin_prior(scene.model.skin.logits, scene.init_logits)
            disp = scene.model.displacement_offsets()
            if disp is not None:
                terms["displacement"] = w.displacement * displacement_prior(disp, scene.size)
            kind = self.cfg.pose_prior.kind
            if kind == "rest":
                terms["pose"] = (
                    self.sequence_scale
                    * w.pose_prior
                    * pose_prior(scene.rotations[self.lo : self.hi], scene.model.rest_rotation)
                )
            elif kind == "clips":
                q = scene.rotations[frames]
                terms["pose"] = w.pose_prior * clip_pose_loss(q, scene.model.rest_rotation, scene.clip_stats)
            elif kind == "motion":
                terms["pose"] = w.pose_prior * scene.sequence_prior.loss(scene.rotations, frames)
            if w.ground_contact > 0 or w.smooth_3d > 0 or self.joints is not None:
                size = scene.size * scene.model.global_scale().detach()  # a tensor: no host sync
            if w.ground_contact > 0:
                body = body_frame(verts, scene.root_rotation[frames], scene.root_translation[frames])
                self.lowest[frames - self.sequence_from] = lowest_heights(body.detach())
                ground = ground_height(self.lowest)
                terms["ground"] = w.ground_contact * (
                    sinking_loss(body, ground, size) + foot_sliding_loss(body, ground, size)
                )
            if w.smooth_3d > 0:
                terms["smooth_3d"] = w.smooth_3d * vertex_acceleration_loss(verts, size)
            if self.joints is not None:
                body = body_frame(posed.joints, scene.root_rotation[frames], scene.root_translation[frames])
                rows = frames - self.sequence_from
                self.joints[rows] = body.detach()
                # The window's frames live, the others as last posed: the clip's statistics.
                clip = self.joints.index_put((rows,), body)
                normal, offset, pairs = scene.model.mirrored_joints()
                terms["gait"] = w.gait_symmetry * gait_symmetry_loss(
                    clip, pairs, normal, offset.detach(), size
                )
            if w.edge_stretch > 0:
                if self.edges is None:
                    self.edges = mesh_edges(scene.faces)
                assert rest is not None
                terms["edge_stretch"] = w.edge_stretch * edge_stretch_loss(verts, rest, self.edges)
            if self.colours is not None:
                valid = (tg.masks.coverage[frames] > 0.5).to(verts.dtype) * weight[:, None, None]
                terms["photo"] = w.photometric * photometric_loss(
                    verts, scene.faces, cam, self.colours, tg.colours[frames], valid
                )
            if scene.joint_limits is not None and w.joint_limits > 0:
                q = scene.rotations[frames]
                terms["limits"] = w.joint_limits * joint_limit_loss(
                    q, scene.model.rest_rotation, scene.joint_limits
                )
        total = torch.stack(list(terms.values())).sum()  # one operator, not one addition per term
        return total, terms

    def pair_overflows(self) -> int:
        """How many of this stage's device renders left (face, pixel) pairs out before their
        renderer's budget grew (`zooctl.render.windows.PairBudget`; renderers without one: 0)."""
        for b in self.budgets:
            b.check()
        return sum(b.overflows for b in self.budgets)

    def step(self, opt: torch.optim.Optimizer, it: int) -> dict[str, Tensor]:
        """One optimiser step; its weighted terms and ``total`` as detached 0-d tensors, read by
        the caller when it needs the numbers (`TermLog`): nothing here waits for the device."""
        frames = self.window()
        opt.zero_grad(set_to_none=True)
        total, terms = self.loss_terms(frames, it)
        total.backward()
        # Lazy Adam for per-frame parameters: frames outside the batch keep their values (their
        # stale momentum would otherwise move them without any evidence). Whole tensors and a
        # mask, not boolean indexing, which would wait for the device.
        moved = torch.zeros(self.scene.num_frames, dtype=torch.bool, device=frames.device)
        moved[frames] = True
        moved[: self.lo] = False
        saved = [p.detach().clone() for p in self.scene.per_frame_parameters()]
        opt.step()
        with torch.no_grad():
            for p, old in zip(self.scene.per_frame_parameters(), saved, strict=True):
                p.copy_(torch.where(moved.view(-1, *([1] * (p.dim() - 1))), p, old))
        out = {k: v.detach() for k, v in terms.items()}
        out["total"] = total.detach()
        return out


class TermLog:
    """Each step's loss terms, read back from the device a batch of steps at a time: one host sync
    per ``every`` steps instead of one per term and step. ``flush`` appends the numbers to
    ``history`` and hands each step's to ``on_step`` (the progress bar)."""

    def __init__(self, history: list[dict[str, float]], on_step, every: int = 16) -> None:
        self.history, self.on_step, self.every = history, on_step, every
        self.pending: list[dict[str, Tensor]] = []

    def add(self, terms: dict[str, Tensor]) -> None:
        self.pending.append(terms)
        if len(self.pending) >= self.every:
            self.flush()

    def flush(self) -> None:
        pending, self.pending = self.pending, []
        if not pending:
            return
        values = torch.stack([v.float().reshape(()) for d in pending for v in d.values()]).tolist()
        rows, i = [], 0
        for d in pending:
            rows.append(dict(zip(d, values[i : i + len(d)], strict=True)))
            i += len(d)
        self.history.extend(rows)  # all of them before the reporter, which may raise (Ctrl-C)
        for row in rows:
            self.on_step(row)


@torch.no_grad()
def mask_iou(scene: FitScene, masks: np.ndarray, batch: int = 16) -> np.ndarray:
    """(T,) IoU between the fitted hard silhouettes and the binary masks (T, h, w), at the fit size;
    NaN on frames whose mask is empty."""
    from ..render.raster import rasterize

    out = []
    for s in range(0, scene.num_frames, batch):
        idx = torch.arange(s, min(s + batch, scene.num_frames), device=scene.rotations.device)
        v = scene.pose(idx).vertices
        sil = rasterize(v, scene.faces, scene.camera(len(idx))).mask.cpu().numpy()
        out.append(silhouette_iou(sil, masks[idx.cpu().numpy()]))
    return np.concatenate(out)
