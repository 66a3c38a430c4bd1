"""The depth-mirror trial: which of two views with one silhouette the fit starts from.

A view of an animal and its mirror in depth (the animal reflected front to back through its own
centre: root rotation ``M_z R S``, with ``S`` the template's mirror plane) cast the same
silhouette, so the camera search cannot tell them apart and picks either. What tells them apart
in the world is the camera's height: the depth mirror of a view from above is a view from below,
and people film animals from above or level far more often than from below. So when the
search's start sees the animal from below, the fit also tries the start's depth mirror (a trial:
the beginning of the fit, paused) and keeps the mirror unless its trial mask IoU falls more than
``camera.mirror_margin`` (the trials' own noise) below the search's. Where the camera's turn is
read from the background, each trial's IoU is first less `TRIAL_WORLD_SPREAD_WEIGHT` times how far
its body turned in the world (`trial_world_spread`), as the template trials score: a start facing
the wrong way matches an orbiting camera's outlines by spinning its body. Nothing is tried when the
camera's rotations are known: their motion tells the two views apart (`initialise_camera`).
The mirror itself, and the camera's elevation, are `zooctl.fit.depth_mirror`'s (`fit_video`
applies them at its start).

``camera.mirror_trial`` says for which templates: ``given`` (default) only for a template the
user named (``--template``), as a retrieved template is another animal, whose trial IoU does not
tell the better view (BENCHMARKS.md, Fit); ``always`` for retrieval's candidates too; ``never``.

``camera.start_trial = "steady"`` (`zooctl.fit.named_start.start_trial`, a named template only)
tries two starts the same way: the camera search's greedy track and its steady turn
(`zooctl.fit.camera_init`), kept by the fit's loss (`trial_loss`) at ``camera.start_trial_at``
rather than by IoU.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .run import FitResult, Reporter, fit_video, trial_camera_turn

if TYPE_CHECKING:
    from ..asset import RiggedAsset
    from .config import FitConfig
    from .inputs import FitVideo


# Trial IoU a degree of a trial body's turn in the world costs (`trial_world_spread`, only where
# the camera turns): chosen leave-one-video-out on the 28 world-background videos for the template
# trials (BENCHMARKS.md, Fit: the body's turn in the world picks the template); the depth-mirror
# trial weighs its two starts by it too.
TRIAL_WORLD_SPREAD_WEIGHT = 0.016


def mirror_wanted(cfg: FitConfig, template_given: bool) -> bool:
    """Whether ``camera.mirror_trial`` asks for the check on this template (module docstring)."""
    mode = cfg.camera.mirror_trial
    return mode == "always" or (mode == "given" and template_given)


@dataclass
class TrialResult:
    """A trial's mask IoU at its pause (`trial_iou`), how far its template's surface moved to get
    there (`trial_displacement`), its paused state, what `trial_with_mirror` tried (None for
    a continued trial), and, where ``trials.view_consistency`` asks for it and the camera turns,
    its `trial_view_consistency`."""

    iou: float
    displacement: float
    state: dict[str, Any] | None
    view: dict[str, Any] | None = None
    consistency: float | None = None
    seconds: float | None = None  # its wall, where `zooctl.fit.trial_pool` ran it


def trial_iou(result: FitResult) -> float:
    """Mean input-view mask IoU of a (trial) fit; frames with an empty mask have none (NaN)."""
    return float(np.nanmean(result.iou)) if np.isfinite(result.iou).any() else 0.0


def trial_displacement(result: FitResult) -> float:
    """Mean length of the displacement field's offsets over the template's size (0 without a
    field): how much a template had to change its shape to fit the video's silhouettes."""
    import torch

    with torch.no_grad():
        disp = result.scene.model.displacement_offsets()
    return 0.0 if disp is None else float(disp.norm(dim=-1).mean()) / result.scene.size


def trial_world_spread(state: dict[str, Any] | None, turn: np.ndarray | None) -> float | None:
    """How far a paused trial's body turns in the world: the mean angle (degrees) of each frame's
    root rotation, the camera's turn taken out (``turn``, `zooctl.fit.run.trial_camera_turn`),
    from their mean. None without a turn or a state. A template of the animal's shape follows an
    orbiting camera with a body that turns as the animal does; one of another shape matches each
    frame's outline by turning the body where the camera went round it."""
    from ..geometry import quat_to_matrix, rotation_angle_deg

    if state is None or turn is None:
        return None
    q = state["scene"]["root_rotation"].detach().cpu().numpy().astype(np.float64)
    if len(q) != len(turn):
        return None
    R = quat_to_matrix(q / np.linalg.norm(q, axis=-1, keepdims=True))
    world = np.transpose(turn, (0, 2, 1)) @ R
    U, _, Vt = np.linalg.svd(world.sum(0))  # the chordal mean rotation
    mean = U @ np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))]) @ Vt
    return float(np.mean([rotation_angle_deg(w @ mean.T) for w in world]))


def trial_view_consistency(
    result: FitResult,
    turn: np.ndarray | None,
    sources: int = 4,
    step: int = 3,
    min_turn_deg: float = 20.0,
) -> float | None:
    """How well a trial's body, seen from the video's other views, matches the masks there: the
    body posed at each of ``sources`` frames t0, turned by the camera's turn from t0 to t
    (``turn`` (T, 3, 3), `zooctl.fit.run.trial_camera_turn`) about its centre and placed on frame
    t's fitted centre, against frame t's mask (every ``step``-th frame), mean IoU at the input
    resolution over the pairs whose camera turned at least ``min_turn_deg`` degrees. The video's
    own frames as held-out views: a template of the animal's shape keeps matching when the camera
    has gone round it; one of another shape matches each outline only as posed for it. None
    without a turn or such pairs. The animal's own motion between t0 and t lowers every
    candidate's figure (BENCHMARKS.md, "The video's own other views score the trials")."""
    import torch

    from ..geometry import silhouette_iou
    from ..render.raster import rasterize

    scene = result.scene
    T = scene.num_frames
    if turn is None or len(turn) != T or T < 2:
        return None
    masks = np.asarray(result.video.masks[:T]).astype(bool)
    cam = result.input_camera().to(scene.rotations.device)
    with torch.no_grad():
        verts = scene.pose().vertices  # (T, V, 3) in the fit's world frame
    centre = verts.mean(1, keepdim=True)
    turn_t = torch.as_tensor(turn, dtype=verts.dtype, device=verts.device)
    targets = torch.arange(0, T, step, device=verts.device)
    ious: list[float] = []
    for t0 in np.unique(np.linspace(0, T - 1, sources).round().astype(int)):
        rel = turn_t[targets] @ turn_t[int(t0)].T  # (S, 3, 3): t0's view turned to each t's
        cos = ((rel.diagonal(dim1=-2, dim2=-1).sum(-1) - 1.0) / 2.0).clamp(-1.0, 1.0)
        far = torch.rad2deg(torch.arccos(cos)) >= min_turn_deg  # each turn's angle
        if not bool(far.any()):
            continue
        sel = targets[far]
        body = (verts[int(t0)] - centre[int(t0)])[None] @ rel[far].transpose(1, 2) + centre[sel]
        seen = masks[sel.cpu().numpy()]
        for s in range(0, len(sel), 8):
            part = body[s : s + 8]
            sil = rasterize(part, scene.faces, cam.expand(len(part))).mask.cpu().numpy()
            ious.extend(silhouette_iou(sil, seen[s : s + 8]).tolist())
    ious = [x for x in ious if np.isfinite(x)]
    return float(np.mean(ious)) if ious else None


def trial_with_mirror(
    video: FitVideo,
    template: RiggedAsset,
    cfg: FitConfig,
    reporter: Reporter | None = None,
    checkpoint: Callable[[dict[str, Any]], None] | None = None,
    mirror: bool = True,
    pause_at: int | None = None,
    length: float = 1.0,
    found: dict[str, Any] | None = None,
) -> TrialResult:
    """The template's trial (`fit_video` paused after ``pause_at`` stage-2 iterations, by default
    ``cfg.trials.iters``) and, when ``mirror`` and its start sees the animal from below, its depth
    mirror's, compared at that pause (module docstring).

    Returns the kept trial: its IoU, displacement, paused state to continue from, and what was
    tried (``view``: also stored in the state's ``camera_init["view_trial"]`` for fit.json).
    ``checkpoint``: as `fit_video`'s, for both trials (each is a fit that a resume can finish).
    ``length``: `fit_video`'s (the template's body made that much longer first); ``found``:
    `fit_video`'s (a camera search already made, for both starts)."""
    pause_at = cfg.trials.iters if pause_at is None else pause_at
    t = time.perf_counter()
    search = fit_video(
        video, template, cfg, reporter, checkpoint, pause_at=pause_at, length=length, found=found
    )
    search_s = time.perf_counter() - t
    iou = trial_iou(search)
    elevation = float(search.camera_init["elevation_deg"])
    info: dict[str, Any] = {"start": "search", "elevation_deg": round(elevation, 1)}
    kept = search
    if mirror and elevation < 0.0 and video.camera_rotations is None and cfg.ablation.optimise:
        if reporter is not None:
            reporter.message(
                f"the start sees {template.name} from below ({elevation:.0f} deg): trying its depth mirror"
            )
        t = time.perf_counter()
        mirrored = fit_video(
            video,
            template,
            cfg,
            reporter,
            checkpoint,
            pause_at=pause_at,
            start="mirror",
            length=length,
            found=search.search,  # the search's own camera search: not made again
        )
        mirror_s = time.perf_counter() - t
        m_iou = trial_iou(mirrored)
        info["trial_iou"] = {"search": round(iou, 4), "mirror": round(m_iou, 4)}
        # the trial not kept: the time the mirror check added to the fit
        info["extra_seconds"] = round(mirror_s, 2)
        turn = trial_camera_turn(video, cfg)
        spreads = [trial_world_spread(r.paused, turn) for r in (search, mirrored)]
        cost = [0.0, 0.0]
        if spreads[0] is not None and spreads[1] is not None:
            info["world_spread_deg"] = {"search": round(spreads[0], 2), "mirror": round(spreads[1], 2)}
            cost = [TRIAL_WORLD_SPREAD_WEIGHT * sp for sp in spreads]
        if m_iou - cost[1] >= iou - cost[0] - cfg.camera.mirror_margin:
            info["start"] = "mirror"
            info["extra_seconds"] = round(search_s, 2)
            kept, iou = mirrored, m_iou
    state = kept.paused
    if state is not None:
        state["camera_init"] = dict(state["camera_init"], view_trial=info)
    return TrialResult(iou, trial_displacement(kept), state, info, _consistency(kept, video, cfg))


def _consistency(result: FitResult, video: FitVideo, cfg: FitConfig) -> float | None:
    """The trial's `trial_view_consistency` where the trial score weighs it, else None."""
    if cfg.trials.view_consistency <= 0:
        return None
    return trial_view_consistency(result, trial_camera_turn(video, cfg))


def continue_trial(
    video: FitVideo,
    template: RiggedAsset,
    cfg: FitConfig,
    state: dict[str, Any],
    pause_at: int,
    reporter: Reporter | None = None,
) -> TrialResult:
    """A paused trial (``state``) fitted on to ``pause_at`` stage-2 iterations and paused again.
    The same fit as a trial paused there in one go."""
    res = fit_video(video, template, cfg, reporter, resume=state, pause_at=pause_at)
    return TrialResult(
        trial_iou(res), trial_displacement(res), res.paused, None, _consistency(res, video, cfg)
    )


def trial_loss(state: dict[str, Any] | None, last: int = 50) -> float:
    """Mean total loss over a paused trial's last ``last`` stage-2 iterations (inf without any):
    each iteration sees another batch of frames, so one iteration's loss is noisy."""
    totals = [h["total"] for h in (state or {}).get("history", {}).get("stage2", [])[-last:]]
    return float(np.mean(totals)) if totals else float("inf")
