"""Typed configuration of a CASA fit, with the ``fast`` and ``quality`` presets.

Every run saves its full configuration as JSON (``schemas/fit_config.schema.json``) beside its
outputs, so a fit can be repeated or resumed exactly. A config file given with ``--config``
may hold any subset of the fields; it is applied on top of the chosen preset, and command-line
options are applied last.
"""

from __future__ import annotations

import dataclasses
import json
import math
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import InputError, UsageError
from .config_spec import check_fields, spec

CONFIG_VERSION = 1
POSE_PRIORS = ("none", "rest", "clips", "motion")
MIRROR_TRIALS = ("given", "always", "never")
FOCAL_GUESSES = ("normal", "search")
TRACKERS = ("greedy", "steady")
START_TRIALS = ("none", "steady")
CAMERA_MOTIONS = ("given", "background", "none")
SEARCH_OVER = ("head", "both")
DEPTH_STARTS = ("box", "trend", "held")
PRESET_NAMES = ("fast", "quality")
_RATE = {"exclusiveMinimum": 0}
_WEIGHT = {"minimum": 0}


@dataclass
class CameraConfig:
    """Supplement I: focal / viewpoint search on the mask loss, then local refinement."""

    focal: float | None = spec(
        None,
        help="pixels at the input resolution; null: from lens_35mm, the video's lens, else focal_guess",
        **_RATE,
    )
    lens_35mm: float | None = spec(
        None,
        help="the lens as a 35 mm-equivalent focal length (mm), when focal is null; null: the lens the "
        "video records (zooctl.video.lens), else focal_guess",
        minimum=1,
        maximum=5000,
    )
    focal_guess: str = spec(
        "normal",
        help="with no focal or lens known (zooctl fit's job): normal (a normal lens, 43 mm 35 mm-equivalent: "
        "the focal is the frame's diagonal) or search (the camera search picks among fov_candidates by "
        "silhouette IoU)",
        enum=FOCAL_GUESSES,
    )
    fov_candidates: list[float] = spec(
        factory=lambda: [30.0, 45.0, 60.0],
        help="vertical fields of view (degrees) the camera search tries when the focal is not known",
        minItems=1,
    )
    azimuths: int = spec(12, help="viewpoints sampled on the sphere: azimuth x elevation", minimum=1)
    elevations: list[float] = spec(factory=lambda: [-15.0, 10.0, 35.0], help="degrees", minItems=1)
    rolls: list[float] = spec(factory=lambda: [0.0], help="degrees", minItems=1)
    search_size: int = spec(64, help="image size (px, longest side) of the search renders", minimum=8)
    search_frames: int = spec(3, help="frames scored per candidate", minimum=1)
    search_over: str = spec(
        "head",
        help="where the camera's turn is read (camera.motion), which frames rank the distinct starts the "
        "tracker follows: head (search_frames of the first track_every frames) or both (those, and as many "
        "more ranked over keyframes spread over the whole clip, each view carried there by the camera's "
        "turn); the track that matches its keyframes best is kept",
        required=False,
        enum=SEARCH_OVER,
    )
    track_every: int = spec(6, help="keyframes for the per-frame root rotation tracking", minimum=1)
    track_step: float = spec(15.0, help="degrees of the local tracking grid", minimum=0)
    track: str = spec(
        "greedy",
        help="how the root rotation is followed over the keyframes: greedy (each keyframe the best small "
        "turn of the one before) or steady (a start and a steady turn about the animal's up axis scored "
        "over the whole video, then each keyframe the best small turn of that prediction)",
        enum=TRACKERS,
    )
    # held since 2026-12-07: own rigs, retrieved templates and held-out animals all closer from the
    # sides (BENCHMARKS.md, "Each frame's starting distance held").
    depth: str = spec(
        "held",
        help="each frame's starting distance from the camera, its place in the image kept: held (the median "
        "over the frames of each frame's own box alignment's distance), trend (the least-squares line of "
        "those distances' logs over time, for an animal walking towards or away from the camera) or box "
        "(each frame's own: a template turned wrongly in a frame fills that frame's box by moving nearer "
        "or further instead of turning)",
        required=False,
        enum=DEPTH_STARTS,
    )
    motion: str = spec(
        "given",
        help="the camera's turn between frames read from the background's motion outside the animal "
        "(zooctl.video.camera_motion) carries the tracker's prediction, and a few distinct starts are "
        "tracked so, the best kept: given (for a template the user named), background (every template, "
        "retrieval's candidates too), none (the tracker assumes a camera at rest). Pairs of frames it "
        "cannot read count as at rest, a camera turning less than track_step over the video as at rest; "
        "known camera rotations take precedence. Unless none, the template trials also read it to score "
        "how far each trial's body turns in the world (zooctl.fit.template.trial_score)",
        enum=CAMERA_MOTIONS,
    )
    # On since 2026-12-06: a truer 3D on the still and world-background own rigs and on 30 held-out
    # ones, on in every leave-one-video-out fold, for one more trial's time (BENCHMARKS.md, "The
    # start trial out of sample", "The start trial compared later").
    start_trial: str = spec(
        "steady",
        help="for a template the user named: steady (the fit also starts from the steady track, both "
        "fitted to stage-2 iteration start_trial_at, and goes on from the one with the lower mean loss "
        "over its last 50 iterations) or none (the greedy track alone)",
        enum=START_TRIALS,
    )
    # 400 since 2026-12-06: chosen in every leave-one-video-out fold of 58 over 200-1000, where the
    # losses pick the better start more often than at the trials' pause (BENCHMARKS.md, "The start
    # trial compared later").
    start_trial_at: int = spec(
        400,
        help="the stage-2 iteration at which the start trial compares its two starts (each start's "
        "depth-mirror check stays at trials.iters; at least that, at most the stage's length)",
        minimum=1,
    )
    # A start seeing the animal from below is tried against its depth mirror (zooctl.fit.view_trial),
    # kept unless its trial IoU is more than the margin (the trials' noise) lower: retrieved
    # templates are other animals, whose trial IoU misled.
    mirror_trial: str = spec(
        "given",
        help="when to try the depth mirror of a start seeing the animal from below: given (a template "
        "the user named), always, never",
        enum=MIRROR_TRIALS,
    )
    mirror_margin: float = spec(
        0.01, help="the mirror is kept unless its trial IoU is this much lower", minimum=0, exclusiveMaximum=1
    )


@dataclass
class StageConfig:
    """One optimisation stage (Adam, betas 0.9/0.999)."""

    iters: int = spec(60, help="optimisation steps (more for clips over schedule_frames)", minimum=0)
    lr: float = spec(
        5e-2, help="learning rate of root transforms, skinning logits (and joints unless lr_joints)", **_RATE
    )
    lr_shape: float = spec(
        1e-3, help="learning rate of the global scale, bone scales and displacement field", **_RATE
    )
    # Adam moves every joint about as far per step however weakly the silhouettes constrain it: a
    # lower rate keeps a good pose (a template of the animal itself), a higher one lets another
    # animal's template deform (BENCHMARKS.md, "The joints' learning rate").
    lr_joints: float | None = spec(None, help="stage 2's joint rotations; null: lr", required=False, **_RATE)
    # A template the user named is as a rule a rig of the animal itself, which needs the lower
    # rate; retrieval's are other animals' (which must bend further). `for_named_template` applies it.
    lr_joints_given: float | None = spec(
        None,
        help="stage 2's joint rotations when the template was named (--template), not retrieved; null: lr_joints",
        required=False,
        **_RATE,
    )
    # A retrieved template's shape moves further after its trials than in them: a freer shape in
    # the trials flatters wrong templates (BENCHMARKS.md, "The shape freer for the winner only").
    lr_shape_given: float | None = spec(
        None,
        help="stage 2's shape rate (lr_shape) when the template was named (--template), not retrieved; "
        "null: lr_shape",
        required=False,
        **_RATE,
    )
    batch: int = spec(
        8, help="frames per step (stage 2: a contiguous window, so flow sees frame pairs)", minimum=1
    )
    renderer: str = spec(
        "soft",
        help="a registered silhouette renderer (soft, fast or a plugin's); checked against the plugin "
        "registry at run time, not here",
        minLength=1,
    )
    lr_final: float = spec(
        1.0,
        help="learning rates decay (cosine) to this fraction of theirs by the last step",
        required=False,
        exclusiveMinimum=0,
        maximum=1,
    )


@dataclass
class LossWeights:
    """lambda1 E_cue (mask + beta * flow) + lambda2 E_smooth + lambda3 E_symm + regularisers."""

    mask: float = spec(1.0, help="lambda1 (soft-silhouette IoU loss)", required=False, **_WEIGHT)
    contour: float = spec(
        0.5, help="vertices outside the mask, mask far from vertices (was dt)", required=False, **_WEIGHT
    )
    flow: float = spec(
        0.05, help="beta: mean |rendered - observed flow| in fit-image pixels", required=False, **_WEIGHT
    )
    smooth: float = spec(10.0, help="lambda2: CASA eq. 6 on joint rotations", required=False, **_WEIGHT)
    # Off by default (BENCHMARKS.md, Fit): it helps a video's own rig in 3D, but retrieved
    # templates and real videos fitted with a starter template lose input IoU.
    smooth_start: float = spec(
        0.0,
        help="stage 2's smoothness weight at its first iteration, decaying geometrically to smooth by "
        "the fraction smooth_until of its iterations (0, the default: smooth throughout)",
        required=False,
        **_WEIGHT,
    )
    smooth_until: float = spec(
        0.5, help="a fraction of stage 2's iterations", required=False, exclusiveMinimum=0, maximum=1
    )
    root_smooth: float = spec(
        10.0, help="smoothness of the per-frame root transform", required=False, **_WEIGHT
    )
    symmetry: float = spec(
        1.0, help="lambda3: CASA eq. 7 (relative to the template size squared)", required=False, **_WEIGHT
    )
    bone_length: float = spec(0.1, help="bone scales near 1 and left/right equal", required=False, **_WEIGHT)
    skin_prior: float = spec(
        0.01, help="skinning weights near the template's (KL)", required=False, **_WEIGHT
    )
    displacement: float = spec(
        1.0, help="mean squared displacement (relative to the template size)", required=False, **_WEIGHT
    )
    pose_prior: float = spec(
        0.01, help="joint rotations near the prior (pose_prior.kind)", required=False, **_WEIGHT
    )
    joint_limits: float = spec(
        0.0,
        help="rotations beyond the template clips' joint ranges, widened by pose_prior.limit_margin_deg (0: off)",
        required=False,
        **_WEIGHT,
    )
    scale_prior: float = spec(
        0.01, help="log global scale near 0 (the template's size)", required=False, **_WEIGHT
    )
    # Off by default, like the two below: measured on the benchmark before any became a default
    # (BENCHMARKS.md, Fit).
    ground_contact: float = spec(
        0.0,
        help="stage 2: no vertex below the ground (a plane of the root's frame at the frames' median "
        "lowest height) and no sliding along it of the vertices touching it (0: off)",
        required=False,
        **_WEIGHT,
    )
    smooth_3d: float = spec(
        0.0,
        help="stage 2: squared acceleration of the posed vertices in world space over a step's "
        "frames, relative to the body size squared (0: off)",
        required=False,
        **_WEIGHT,
    )
    edge_stretch: float = spec(
        0.5,
        help="stage 2: each posed edge's stretch or squeeze beyond 1.5 times its length in the rest "
        "shape, squared (of the log), which keeps the skinning from tearing the surface (0: off; "
        "2 tears less still for a little input IoU)",
        required=False,
        **_WEIGHT,
    )
    gait_symmetry: float = spec(
        0.0,
        help="stage 2: mirrored joints (left reflected, right) with the same mean position and "
        "spread over the clip in the root's frame, as in a walk or trot (0: off)",
        required=False,
        **_WEIGHT,
    )
    photometric: float = spec(
        0.0,
        help="stage 2: the surface in learned per-vertex colours, rendered through the z-buffer, "
        "against the frame's colours inside the mask, after a per-frame gain (mean L1 of sRGB; "
        "0: off)",
        required=False,
        **_WEIGHT,
    )


@dataclass
class TemplateTrials:
    """Retrieval's best candidates each get a short fit, and the fit of the template whose trial
    scores best goes on from its trial to the full length: a check of the embedding ranking by the
    fit itself (it corrects retrievals like Dolphin -> Stegosaurus). The score
    (`zooctl.fit.template.trial_score`) is the trial's mask IoU, plus the semantic term, less what
    the template's surface had to move to fit. Only when the template was retrieved."""

    candidates: int = spec(3, help="1: fit the top retrieval result directly", required=False, minimum=1)
    iters: int = spec(
        200,
        help="stage-2 iterations of each trial: the first ones of the full fit's schedule, so the "
        "winner's fit goes on from its trial",
        required=False,
        minimum=0,
    )
    lr_shape: float | None = spec(
        1e-3,
        help="stage 2's shape rate (stage2.lr_shape) in the trials; the winner's fit goes on from its "
        "trial at stage2.lr_shape. null: stage2.lr_shape throughout",
        required=False,
        **_RATE,
    )
    margin: float = spec(
        0.0,
        help="a trial wins only if no candidate earlier in retrieval's order scores within this much of "
        "it (the trial mask IoU, plus the semantic term, less the displacement's cost)",
        required=False,
        minimum=0,
        exclusiveMaximum=1,
    )
    longer: float = spec(
        1.0,
        help="the winning template is tried once more with its body this many times longer along its "
        "longest axis (the bones along it stretched, the bone-length prior held there), and the longer "
        "body kept where its trial scores better: a template shorter than the animal otherwise lies "
        "across the view where the animal points away. 1: not tried",
        required=False,
        minimum=1,
        maximum=3,
    )
    carried: bool = spec(
        True,
        help="where the camera turns round the animal (its turn read from the background, at least "
        "camera.track_step over the trial's frames), each candidate is also tried from a start "
        "carried by the camera's turn (camera.motion background), and its trial is the start that "
        "scores better (compared at carried_at). Only there: elsewhere the two starts are one. About "
        "1.3-1.4 times the fit time where the camera turns; false: the search's start alone",
        required=False,
    )
    carried_at: int | None = spec(
        100,
        help="with two starts (carried), the stage-2 iteration where each candidate's two trials are "
        "compared and the one that scores lower stops; the other goes on to iters. null: both run to "
        "iters. With prune_at too, both happen at the earlier of the two",
        required=False,
        minimum=0,
    )
    view_consistency: float = spec(
        0.0,
        help="where the camera turns round the animal, the trial score adds this much times the "
        "trial's view consistency (zooctl.fit.view_trial.trial_view_consistency: its body posed at "
        "one frame and turned by the camera's turn, against the masks of frames seen from 20 or more "
        "degrees away; 0..1). 0: not scored",
        required=False,
        minimum=0,
    )
    # Off by default: leave-one-video-out over 58 videos gained nothing (BENCHMARKS.md, "Forty
    # more animals nothing was tuned on").
    sure: float | None = spec(
        None,
        help="where retrieval's first candidate scores at least this much better than every other "
        "(lower, in the fused score's units: each embedder's distances as z-scores across the bank, "
        "plus the semantic term), it is fitted without trials: retrieval is sure of it. null: the "
        "trials always run",
        required=False,
        minimum=0,
    )
    # Successive halving: the trials all stop at a checkpoint, and those clearly behind there
    # (their pick score, as the winner's, more than the margin below the best) go no further.
    prune_at: int | None = spec(
        None,
        help="stage-2 iterations after which a trial whose score (trial mask IoU, plus the semantic "
        "term, less the displacement's cost) is more than prune_margin below the best stops; the "
        "rest go on to iters. null: every trial runs to iters",
        required=False,
        minimum=0,
    )
    prune_margin: float = spec(
        0.05, help="how far below the best trial's score a trial stops at prune_at", required=False, minimum=0
    )
    # box since 2026-12-07: held in the trials moved picks to generic templates, mostly lower
    # (BENCHMARKS.md, "The trials at each frame's own distance, the winner's fit held").
    depth: str | None = spec(
        "box",
        help="camera.depth of the trials alone, where it differs from camera.depth: the candidates are "
        "compared from this start, and the winner's trial is run again from camera.depth's (its "
        "depth-mirror check, carried start and length as in its trial, its camera search the trial's "
        "placed at camera.depth when the trials' is box) for its fit to go on from: one more trial's "
        "time less the search. null: the trials start as the fit does",
        required=False,
        enum=[*DEPTH_STARTS, None],
    )
    workers: int = spec(
        0,
        help="processes the trials (and a named template's two starts, camera.start_trial) run in "
        "side by side on the CPU, sharing the torch threads (zooctl.fit.trial_pool). 0: one per "
        "trial while they are at most twice the threads, else one per thread; 1: one after another "
        "in the fit's own process (so with one CPU thread, or with a plugin registered in that "
        "process alone). On CUDA 0 is one after another too; 2 or more: that many processes side "
        "by side on the fit's GPU",
        required=False,
        minimum=0,
    )


@dataclass
class PosePrior:
    """Which prior ``weights.pose_prior`` weighs (`zooctl.fit.pose_prior`): ``none``, ``rest``
    (rotations near the rest pose), ``clips`` (per-joint rotation statistics of the template's
    own clips, deviations floored at ``min_std_deg``) or ``motion`` (a trained motion prior
    scoring windows of the fitted motion). ``limit_margin_deg`` widens the clips' joint ranges on
    each side for the joint-limit term (``weights.joint_limits``, with any kind)."""

    kind: str = spec("rest", help="none, rest, clips or motion", required=False, enum=POSE_PRIORS)
    min_std_deg: float = spec(10.0, help="floor of the clips' per-joint deviations", required=False, **_RATE)
    motion: str | None = spec(
        None,
        help="the motion prior of kind motion: its name in the store or its folder; null: the store's latest",
        required=False,
    )
    limit_margin_deg: float = spec(
        30.0,
        help="degrees the clips' joint ranges are widened on each side for weights.joint_limits",
        required=False,
        minimum=0,
        maximum=180,
    )


@dataclass
class Ablation:
    """Switches for CASA's ablations (tables 2-5)."""

    flow: bool = spec(True, required=False)
    symmetry: bool = spec(True, required=False)
    smoothness: bool = spec(True, required=False)
    stretch: bool = spec(True, required=False)
    displacement: bool = spec(True, required=False)
    learn_skinning: bool = spec(True, required=False)
    # On since 2026-11-29: without it a learned skinning cracks the flat-shaded templates open
    # (17-42 % of their edges; BENCHMARKS.md, "Shared seams and the edge-stretch term").
    share_seams: bool = spec(
        True,
        help="copies of a template vertex at one position (a flat-shaded or UV-split mesh's seams) "
        "learn one set of skinning weights, so the surface cannot crack open along them",
        required=False,
    )
    # On since 2026-12-02 (BENCHMARKS.md, "Bones that thicken across themselves").
    girth: bool = spec(
        True,
        help="each bone also scales the template across itself, in every direction: what a silhouette "
        "shows of a body's thickness is carried to the side it does not show",
        required=False,
    )
    optimise: bool = spec(True, help="false: retrieval (template and camera) only", required=False)


# The template is the animal's own rig: its shape, bone lengths and skinning stay, and only the
# pose, the root and the camera are fitted (`zooctl fit --keep-shape`, `bench run --ablation
# shape-kept`; BENCHMARKS.md, "A torn surface").
KEEP_SHAPE: dict[str, Any] = {
    "ablation": {"learn_skinning": False, "displacement": False, "stretch": False, "girth": False}
}


@dataclass
class FitConfig:
    """A whole fit: image sizes, device, seed, the camera search, two stages and the loss weights."""

    preset: str = spec("fast", enum=PRESET_NAMES)
    device: str = spec("cpu", help="cpu, cuda or cuda:N", pattern="^(cpu|cuda(:[0-9]+)?)$")
    articulation: str = spec(
        "casa",
        help="a registered articulation model (casa, dqs, lbs or a plugin's); checked against the "
        "plugin registry at run time",
        required=False,
        minLength=1,
    )
    seed: int = spec(0)
    fit_size: int = spec(128, help="longest side (px) of the images the losses see", minimum=16, maximum=1024)
    max_frames: int | None = spec(
        None, help="fit only the first frames; null: all", required=False, minimum=1
    )
    schedule_frames: int = spec(
        100,
        help="the stages' iterations are for clips up to this many frames; a longer clip gets "
        "proportionally more (0: the same for every length)",
        required=False,
        minimum=0,
    )
    window_frames: int = spec(
        100,
        help="a longer clip is fitted in windows of at most this many frames: the first as a clip of "
        "its own (body, camera, motion), each later one its frames' motion in its own crop with the body "
        "and the camera held, continuing from the frames before it (0: the whole clip at once)",
        required=False,
        minimum=0,
    )
    soft_sigma: float = spec(
        0.05,
        help="SoftRas sigma (px^2): small, since dense meshes dilate soft silhouettes",
        required=False,
        **_RATE,
    )
    pair_budget: bool = spec(
        False,
        help="the renderers' PyTorch path (a GPU's): a fixed budget of (face, pixel) pairs, so a step "
        "reads nothing back from the device, instead of counting them at every call (off until "
        "measured on a GPU)",
        required=False,
    )
    checkpoint_every: int = spec(
        25, help="steps between saved states (for --resume)", required=False, minimum=0
    )
    hidden: int = spec(64, help="displacement MLP width", required=False, minimum=1)
    camera: CameraConfig = spec(factory=CameraConfig)
    # Learning rates above CASA's with a cosine decay (the joints' lower), and 1,000 stage-2
    # iterations: why and what they were measured to give is in BENCHMARKS.md ("Fit schedule").
    stage1: StageConfig = spec(
        factory=lambda: StageConfig(iters=60, lr=5e-2, lr_shape=5e-2, batch=16, renderer="soft", lr_final=0.1)
    )
    stage2: StageConfig = spec(
        factory=lambda: StageConfig(
            iters=1000,
            lr=3e-2,
            lr_shape=5e-3,
            lr_shape_given=1e-3,
            batch=12,
            lr_final=0.05,
            lr_joints=2e-2,
            lr_joints_given=1e-2,
        ),
        help="stage 2 (articulation) runs at least one iteration",
        only={"iters": {"minimum": 1}},
    )
    weights: LossWeights = spec(factory=LossWeights)
    ablation: Ablation = spec(factory=Ablation)
    trials: TemplateTrials = spec(factory=TemplateTrials, required=False)
    pose_prior: PosePrior = spec(factory=PosePrior, required=False)
    texture: bool = spec(
        True,
        help="bake the video's colours onto the exported character as a UV texture (in an atlas made "
        "for a template without UVs); false keeps the template's",
        required=False,
    )
    schema_version: int = spec(CONFIG_VERSION, const=CONFIG_VERSION)

    # -- serialisation ------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1)

    @classmethod
    def from_dict(cls, data: dict[str, Any], base: FitConfig | None = None) -> FitConfig:
        """Apply ``data`` (any subset of the fields) on top of ``base`` (default: the fast preset).
        ``data`` setting stage 2's ``lr_joints`` without ``lr_joints_given`` sets the joints' rate
        for every template, named ones too; ``lr_shape`` without ``lr_shape_given`` sets the
        shape's for named templates and for the trials (``trials.lr_shape``) too."""
        cfg = base if base is not None else preset("fast")
        _merge(cfg, data, "config")
        stage2 = data.get("stage2") if isinstance(data, dict) else None
        if isinstance(stage2, dict) and "lr_joints" in stage2 and "lr_joints_given" not in stage2:
            cfg.stage2.lr_joints_given = None
        if isinstance(stage2, dict) and "lr_shape" in stage2 and "lr_shape_given" not in stage2:
            cfg.stage2.lr_shape_given = None
            trials = data.get("trials")
            if not (isinstance(trials, dict) and "lr_shape" in trials):
                cfg.trials.lr_shape = None
        return cfg.validate()

    def stage(self, stage: int, num_frames: int | None = None) -> StageConfig:
        """Stage ``stage``'s settings for a clip of ``num_frames`` frames: its iterations scaled
        by ``num_frames / schedule_frames`` when the clip is longer (see ``schedule_frames``)."""
        st = self.stage1 if stage == 1 else self.stage2
        if num_frames is None or self.schedule_frames <= 0 or num_frames <= self.schedule_frames:
            return st
        return dataclasses.replace(st, iters=math.ceil(st.iters * num_frames / self.schedule_frames))

    def windows(self, num_frames: int) -> list[tuple[int, int]]:
        """The (start, end) frame ranges a clip of ``num_frames`` frames is fitted in, in order
        (see ``window_frames``): the first ``window_frames`` frames, then the rest in equal
        windows of at most as many."""
        n = self.window_frames
        if n <= 0 or num_frames <= n:
            return [(0, num_frames)]
        k = math.ceil((num_frames - n) / n)
        bounds = [0] + [n + ((num_frames - n) * i) // k for i in range(k + 1)]
        return list(zip(bounds[:-1], bounds[1:], strict=True))

    def for_named_template(self) -> FitConfig:
        """This config for a template the user named: stage 2's joints at ``lr_joints_given`` and
        its shape at ``lr_shape_given`` (each when set) instead of ``lr_joints`` and ``lr_shape``,
        and ``camera.motion`` ``given`` as ``background``. A copy; the fit's record keeps what it
        used."""
        out, st = self, self.stage2
        if st.lr_joints_given is not None:
            st = dataclasses.replace(st, lr_joints=st.lr_joints_given)
        if st.lr_shape_given is not None:
            st = dataclasses.replace(st, lr_shape=st.lr_shape_given)
        if st is not self.stage2:
            out = dataclasses.replace(out, stage2=st)
        if out.camera.motion == "given":
            out = out.with_camera_motion("background")
        return out

    def for_trials(self) -> FitConfig:
        """This config for the template trials: stage 2's shape at ``trials.lr_shape`` and the
        camera's starting distances at ``trials.depth`` (each when set). The winner's fit goes on
        with this config's own rate, from its trial run again at ``camera.depth`` where the two
        differ (`zooctl.fit.template.try_candidates`)."""
        cfg, rate, depth = self, self.trials.lr_shape, self.trials.depth
        if rate is not None and rate != self.stage2.lr_shape:
            cfg = dataclasses.replace(cfg, stage2=dataclasses.replace(cfg.stage2, lr_shape=rate))
        if depth is not None and depth != self.camera.depth:
            cfg = dataclasses.replace(cfg, camera=dataclasses.replace(cfg.camera, depth=depth))
        return cfg

    def with_camera_motion(self, motion: str) -> FitConfig:
        """A copy of this config with ``camera.motion`` set to ``motion``."""
        return dataclasses.replace(self, camera=dataclasses.replace(self.camera, motion=motion))

    def keep_shape(self) -> FitConfig:
        """This config with the template's shape, bone lengths and skinning kept (`KEEP_SHAPE`):
        for a template that is the animal's own rig. Changes ``self``; returns it."""
        _merge(self, KEEP_SHAPE, "keep_shape")
        return self

    def validate(self) -> FitConfig:
        """Check every field against its rules (`zooctl.fit.config_spec`), then the components
        against the plugin registry; returns ``self``."""
        iters = self.stage2.iters
        if isinstance(iters, int) and not isinstance(iters, bool) and iters < 1:  # names the options
            raise UsageError(
                f"stage 2 needs at least 1 iteration (--iters or stage2.iters), got {self.stage2.iters}",
                hint=f"the presets run {', '.join(f'{k} {v().stage2.iters}' for k, v in PRESETS.items())}",
            )
        check_fields(self)
        for name in ("stage1", "stage2"):
            _check_registered("renderer", getattr(self, name).renderer, f"{name}.renderer")
        _check_registered("articulation_model", self.articulation, "articulation")
        return self


def _check_registered(kind: str, name: Any, where: str) -> None:
    """Names of components are checked against the plugin registry at run time (not the schema),
    so a plugin's renderer or articulation model is accepted like a built-in one."""
    from ..plugins import get_registry

    known = get_registry().names(kind)
    if name not in known:
        raise UsageError(
            f"{where}: no {kind.replace('_', ' ')} named {name!r}",
            hint=f"registered: {', '.join(known) or 'none'} (see `zooctl plugins`)",
        )


# Config keys renamed since fits were first stored: old name -> new name, per section.
RENAMED = {LossWeights: {"dt": "contour"}}


def _merge(obj: Any, data: dict[str, Any], where: str) -> None:
    if not isinstance(data, dict):
        raise InputError(f"{where} must be a JSON object")
    for old, new in RENAMED.get(type(obj), {}).items():
        if old in data:
            if new in data:
                raise InputError(
                    f"{where}: both {old!r} and its new name {new!r} are given", hint=f"drop {old!r}"
                )
            warnings.warn(
                f"{where}.{old} is deprecated: it is now {where}.{new} (read as that)",
                FutureWarning,
                stacklevel=3,
            )
            data = {new if k == old else k: v for k, v in data.items()}
    names = {f.name: f for f in dataclasses.fields(obj)}
    for key, value in data.items():
        if key not in names:
            raise InputError(f"{where}: unknown field {key!r}", hint=f"fields: {', '.join(names)}")
        cur = getattr(obj, key)
        if dataclasses.is_dataclass(cur):
            _merge(cur, value, f"{where}.{key}")
        else:
            setattr(obj, key, value)


def _fast() -> FitConfig:
    return FitConfig(preset="fast")


def _quality() -> FitConfig:
    # The fast preset fitted 2.4 times as long. Its camera search, template trials, fit image and
    # displacement field stay fast's: quality's own (160 px, a 16 x 4 grid, a wider field) picked
    # worse templates and posed them worse in 3D (BENCHMARKS.md, "The quality preset").
    cfg = FitConfig(preset="quality")
    cfg.stage2.iters = 2400
    return cfg


PRESETS = {"fast": _fast, "quality": _quality}  # PRESET_NAMES, in this order (a test checks)


def preset(name: str) -> FitConfig:
    if name not in PRESETS:
        raise UsageError(f"unknown preset {name!r}", hint=f"use one of {', '.join(PRESETS)}")
    return PRESETS[name]()


def read_config_file(path: Path) -> Any:
    """The JSON of a config file (any subset of `FitConfig`'s fields), or one clear error."""
    from ..files import read_input

    path = Path(path)
    data = read_input(path, "config file", "max_json_mb")  # not a FIFO, nor gigabytes
    try:
        return json.loads(data)
    except (ValueError, RecursionError) as exc:  # UnicodeDecodeError is a ValueError
        raise InputError(f"config file {path} is not valid JSON: {exc}") from None


def load_config(path: Path | None, preset_name: str = "fast") -> FitConfig:
    """The preset, with a JSON config file applied on top (when given)."""
    cfg = preset(preset_name)
    if path is None:
        return cfg
    data = read_config_file(path)
    if isinstance(data, dict) and "preset" in data and data["preset"] != preset_name:
        cfg = preset(str(data["preset"]))
    return FitConfig.from_dict(data, cfg)
