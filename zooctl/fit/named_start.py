"""Where a fit with no template trials behind it starts: a named template's start trial.

``camera.start_trial = "steady"`` (the default, a template the user named) fits the template
from the camera search's greedy track and from its steady turn (`zooctl.fit.camera_init`), each
with its depth-mirror check (`zooctl.fit.view_trial.trial_with_mirror`), to stage-2 iteration
``camera.start_trial_at``, and goes on from the one whose loss is lower there. The two run side by
side where the template trials would (`zooctl.fit.trial_pool`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from .trial_pool import Trial, run_trials
from .view_trial import TrialResult, mirror_wanted, trial_loss, trial_with_mirror

if TYPE_CHECKING:
    from ..asset import RiggedAsset
    from .config import FitConfig
    from .inputs import FitVideo
    from .run import Reporter


def start_trial(
    video: FitVideo,
    template: RiggedAsset,
    cfg: FitConfig,
    reporter: Reporter | None = None,
    checkpoint: Callable[[dict[str, Any]], None] | None = None,
) -> TrialResult:
    """The template's trial from the camera search's greedy track and from its steady track
    (``camera.track``), each with its depth-mirror check (`trial_with_mirror`) and fitted on to
    stage-2 iteration ``camera.start_trial_at``; the one whose loss (`trial_loss`) is lower there
    is kept. Silhouette IoU does not tell which start is right (the rest pose fits a wrongly
    turned animal as well), the fit's whole loss mostly does, and more often a few hundred
    iterations after the trials' pause (BENCHMARKS.md, "Where the own rig's novel view is lost
    now", "The start trial compared later"). The kept trial's view records both losses under
    ``start_trial``."""
    at = max(cfg.camera.start_trial_at, cfg.trials.iters)
    names = ("greedy", "steady")
    trials = [
        Trial(template, cfg.trials.iters, mirror_wanted(cfg, True), track=t, then=at, label=f"{t} turn")
        for t in names
    ]
    # side by side where the trials' processes would be (two or more torch threads), else here
    tracks = dict(zip(names, run_trials(video, trials, cfg, reporter, checkpoint), strict=True))
    losses = {k: round(trial_loss(r.state), 6) for k, r in tracks.items()}
    name = "steady" if losses["steady"] < losses["greedy"] else "greedy"
    kept, extra = tracks[name], tracks["greedy" if name == "steady" else "steady"].seconds or 0.0
    info = {"loss": losses, "at": at, "kept": name, "extra_seconds": round(extra, 2)}
    view = dict(kept.view or {}, start_trial=info)
    view["extra_seconds"] = round(float((kept.view or {}).get("extra_seconds") or 0.0) + extra, 2)
    if kept.state is not None:
        kept.state["camera_init"] = dict(kept.state["camera_init"], view_trial=view)
    return TrialResult(kept.iou, kept.displacement, kept.state, view, kept.consistency, kept.seconds)


def template_start(
    video: FitVideo,
    template: RiggedAsset,
    cfg: FitConfig,
    template_given: bool,
    reporter: Reporter | None = None,
    checkpoint: Callable[[dict[str, Any]], None] | None = None,
) -> TrialResult | None:
    """Where a fit with no template trials behind it starts: the kept trial of `start_trial` (a
    named template with ``camera.start_trial = "steady"``, the default, and no known camera
    rotations) or of `trial_with_mirror` (when `mirror_wanted`), or None (the fit starts from the
    camera search as it is). ``checkpoint`` saves each trial as it runs; `fit_job` marks those
    states, so that a fit stopped inside the trials tries them all again on --resume, and saves the
    kept one after."""
    if not cfg.ablation.optimise:
        return None
    # known camera rotations leave one orientation in the world to find: no track to choose
    if template_given and cfg.camera.start_trial == "steady" and video.camera_rotations is None:
        return start_trial(video, template, cfg, reporter, checkpoint)
    if mirror_wanted(cfg, template_given):
        # the fit goes on from the trial kept (as if never paused when nothing was tried)
        return trial_with_mirror(video, template, cfg, reporter, checkpoint)
    return None
