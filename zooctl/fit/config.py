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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import InputError, UsageError

CONFIG_VERSION = 1


@dataclass
class CameraConfig:
    """Supplement I: focal / viewpoint search on the mask loss, then local refinement."""

    focal: float | None = None  # pixels at the input resolution; None: estimate it
    fov_candidates: list[float] = field(default_factory=lambda: [30.0, 45.0, 60.0])  # degrees (vertical)
    azimuths: int = 12  # viewpoints sampled on the sphere: azimuth x elevation
    elevations: list[float] = field(default_factory=lambda: [-15.0, 10.0, 35.0])
    rolls: list[float] = field(default_factory=lambda: [0.0])
    search_size: int = 64  # image size (px, longest side) of the search renders
    search_frames: int = 3  # frames scored per candidate
    track_every: int = 6  # keyframes for the per-frame root rotation tracking
    track_step: float = 15.0  # degrees of the local tracking grid
    # A start seeing the animal from below is tried against its depth mirror (zooctl.fit.view_trial),
    # kept unless its trial IoU is more than the margin (the trials' noise) lower: "given" for a
    # template named by the user (retrieved ones are other animals, whose trial IoU misled), "always", "never".
    mirror_trial: str = "given"
    mirror_margin: float = 0.01


@dataclass
class StageConfig:
    """One optimisation stage (Adam, betas 0.9/0.999)."""

    iters: int = 60
    lr: float = 5e-2  # root transforms, skinning logits (and joint rotations unless lr_joints)
    lr_shape: float = 1e-3  # global scale, bone scales and the displacement field
    # Joint rotations (stage 2); None: ``lr``. Adam moves every joint about as far per step however
    # weakly the silhouettes constrain it: a lower rate keeps a good pose (a template of the animal
    # itself), a higher one lets another animal's template deform (BENCHMARKS.md, "The joints'
    # learning rate").
    lr_joints: float | None = None
    # Joint rotations when the user named the template (``--template``: as a rule a rig of the
    # animal itself, which needs the lower rate) instead of retrieval choosing another animal's
    # (which must bend further); None: ``lr_joints``. `FitConfig.for_named_template` applies it.
    lr_joints_given: float | None = None
    batch: int = 8  # frames per step (stage 2: a contiguous window, so flow sees frame pairs)
    renderer: str = "soft"  # a registered silhouette renderer: soft (SoftRas), fast (splatting), plugins
    lr_final: float = 1.0  # learning rates decay (cosine) to this fraction of theirs by the last step


@dataclass
class LossWeights:
    """lambda1 E_cue (mask + beta * flow) + lambda2 E_smooth + lambda3 E_symm + regularisers."""

    mask: float = 1.0  # lambda1 (soft-silhouette IoU loss)
    contour: float = 0.5  # `contour_loss`: vertices outside the mask, mask far from vertices (was ``dt``)
    flow: float = 0.05  # beta: mean |rendered flow - observed flow| in pixels of the fit image
    smooth: float = 10.0  # lambda2: CASA eq. 6 on joint rotations
    # Stage 2 may start with a stronger smoothness that decays geometrically to ``smooth`` by the
    # fraction ``smooth_until`` of its iterations (`zooctl.fit.stages.smooth_weight`): early, while
    # the limbs find their depth, views of a pose held over frames tie it; then the silhouettes
    # have their say. Off by default (BENCHMARKS.md, Fit): it helps a video's own rig in 3D, but
    # retrieved templates and real videos fitted with a starter template lose input IoU.
    smooth_start: float = 0.0  # 0: ``smooth`` throughout
    smooth_until: float = 0.5
    root_smooth: float = 10.0  # smoothness of the per-frame root transform
    symmetry: float = 1.0  # lambda3: CASA eq. 7 (relative to the template size squared)
    bone_length: float = 0.1  # bone scales near 1 and left/right equal
    skin_prior: float = 0.01  # skinning weights near the template's (KL)
    displacement: float = 1.0  # mean squared displacement (relative to the template size)
    pose_prior: float = 0.01  # joint rotations near the rest pose
    joint_limits: float = 0.0  # rotations beyond the template clips' joint ranges (0: off)
    scale_prior: float = 0.01  # log global scale near 0 (the template's size)


@dataclass
class TemplateTrials:
    """Retrieval's best candidates each get a short fit, and the fit of the template whose
    silhouettes match the video best goes on from its trial to the full length: a check of the
    embedding ranking by the fit itself (it corrects retrievals like Dolphin -> Stegosaurus).
    Only when the template was retrieved."""

    candidates: int = 3  # 1: fit the top retrieval result directly
    # Stage-2 iterations of each trial: the first ones of the full fit's schedule (after the camera
    # search and stage 1), so the winner's fit goes on from its trial.
    iters: int = 200
    # The winner is the first candidate in retrieval's order whose trial mask IoU is within
    # ``margin`` of the best one's (0: the best trial), for users who trust the ranking over small
    # silhouette differences.
    margin: float = 0.0


@dataclass
class PosePrior:
    """Which prior ``weights.pose_prior`` weighs (`zooctl.fit.pose_prior`): ``none``, ``rest``
    (rotations near the rest pose), ``clips`` (per-joint rotation statistics of the template's
    own clips, deviations floored at ``min_std_deg``) or ``motion`` (a trained motion prior
    scoring windows of the fitted motion: ``motion`` names it in the store, or is its folder;
    None: the store's latest). ``limit_margin_deg`` widens the clips' joint ranges on each side
    for the joint-limit term (``weights.joint_limits``, with any kind)."""

    kind: str = "rest"
    min_std_deg: float = 10.0
    motion: str | None = None
    limit_margin_deg: float = 30.0


POSE_PRIORS = ("none", "rest", "clips", "motion")
MIRROR_TRIALS = ("given", "always", "never")


@dataclass
class Ablation:
    """Switches for CASA's ablations (tables 2-5)."""

    flow: bool = True
    symmetry: bool = True
    smoothness: bool = True
    stretch: bool = True
    displacement: bool = True
    learn_skinning: bool = True
    optimise: bool = True  # False: retrieval (template and camera) only


@dataclass
class FitConfig:
    """A whole fit: image sizes, device, seed, the camera search, two stages and the loss weights."""

    preset: str = "fast"
    device: str = "cpu"
    articulation: str = "casa"  # a registered articulation model (`zooctl plugins`): casa, dqs, lbs
    seed: int = 0
    fit_size: int = 128  # longest side (px) of the images the losses see
    max_frames: int | None = None
    # The stages' iterations are for clips up to this many frames; a longer clip gets
    # proportionally more, so each frame gets as many updates (0: the same for every length).
    schedule_frames: int = 100
    soft_sigma: float = 0.05  # SoftRas sigma (px^2): small, since dense meshes dilate soft silhouettes
    checkpoint_every: int = 25  # steps between saved states (for --resume)
    hidden: int = 64  # displacement MLP width
    camera: CameraConfig = field(default_factory=CameraConfig)
    # Learning rates above CASA's with a cosine decay (the joints' lower), and 1,000 stage-2
    # iterations: why and what they were measured to give is in BENCHMARKS.md ("Fit schedule").
    stage1: StageConfig = field(
        default_factory=lambda: StageConfig(
            iters=60, lr=5e-2, lr_shape=5e-2, batch=16, renderer="soft", lr_final=0.1
        )
    )
    stage2: StageConfig = field(
        default_factory=lambda: StageConfig(
            iters=1000, lr=3e-2, lr_shape=1e-3, batch=12, lr_final=0.05, lr_joints=2e-2, lr_joints_given=1e-2
        )
    )
    weights: LossWeights = field(default_factory=LossWeights)
    ablation: Ablation = field(default_factory=Ablation)
    trials: TemplateTrials = field(default_factory=TemplateTrials)
    pose_prior: PosePrior = field(default_factory=PosePrior)
    texture: bool = True  # bake the video's colours onto the exported character (fit/texture.py)
    schema_version: int = CONFIG_VERSION

    # -- serialisation ------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1)

    @classmethod
    def from_dict(cls, data: dict[str, Any], base: FitConfig | None = None) -> FitConfig:
        """Apply ``data`` (any subset of the fields) on top of ``base`` (default: the fast preset).
        ``data`` setting stage 2's ``lr_joints`` without ``lr_joints_given`` sets the joints' rate
        for every template, named ones too."""
        cfg = base if base is not None else preset("fast")
        _merge(cfg, data, "config")
        stage2 = data.get("stage2") if isinstance(data, dict) else None
        if isinstance(stage2, dict) and "lr_joints" in stage2 and "lr_joints_given" not in stage2:
            cfg.stage2.lr_joints_given = None
        return cfg.validate()

    def stage(self, stage: int, num_frames: int | None = None) -> StageConfig:
        """Stage ``stage``'s settings for a clip of ``num_frames`` frames: its iterations scaled
        by ``num_frames / schedule_frames`` when the clip is longer (see ``schedule_frames``)."""
        st = self.stage1 if stage == 1 else self.stage2
        if num_frames is None or self.schedule_frames <= 0 or num_frames <= self.schedule_frames:
            return st
        return dataclasses.replace(st, iters=math.ceil(st.iters * num_frames / self.schedule_frames))

    def for_named_template(self) -> FitConfig:
        """This config for a template the user named: stage 2's joints at ``lr_joints_given``
        (when set) instead of ``lr_joints``. A copy; the fit's record keeps the rate it used."""
        st = self.stage2
        if st.lr_joints_given is None:
            return self
        return dataclasses.replace(self, stage2=dataclasses.replace(st, lr_joints=st.lr_joints_given))

    def validate(self) -> FitConfig:
        if self.preset not in PRESETS:
            raise UsageError(f"unknown preset {self.preset!r}", hint=f"use one of {', '.join(PRESETS)}")
        if self.device not in ("cpu", "cuda") and not self.device.startswith("cuda:"):
            raise UsageError(f"--device {self.device!r} is not cpu or cuda")
        if not 16 <= self.fit_size <= 1024:
            raise UsageError(f"fit_size {self.fit_size} is out of range", hint="use 16 to 1024 pixels")
        for name in ("stage1", "stage2"):
            st: StageConfig = getattr(self, name)
            rates = (st.lr, st.lr_shape) + tuple(
                r for r in (st.lr_joints, st.lr_joints_given) if r is not None
            )
            if st.iters < 0 or st.batch < 1 or min(rates) <= 0:
                raise UsageError(f"{name}: iters >= 0, batch >= 1 and positive learning rates are required")
            if name == "stage2" and st.iters < 1:  # no articulation at all: not a fit
                raise UsageError(
                    f"stage 2 needs at least 1 iteration (--iters or stage2.iters), got {st.iters}",
                    hint=f"the presets run {', '.join(f'{k} {v().stage2.iters}' for k, v in PRESETS.items())}",
                )
            if not 0 < st.lr_final <= 1:
                raise UsageError(f"{name}: lr_final must be in (0, 1]")
            _check_registered("renderer", st.renderer, f"{name}.renderer")
        _check_registered("articulation_model", self.articulation, "articulation")
        if not isinstance(self.texture, bool):
            raise UsageError(f"texture must be true or false, got {self.texture!r}")
        if self.camera.focal is not None and self.camera.focal <= 0:
            raise UsageError(f"--focal {self.camera.focal} must be positive (pixels)")
        if not 0 <= self.camera.mirror_margin < 1:
            raise UsageError(f"camera.mirror_margin {self.camera.mirror_margin} must be in [0, 1)")
        if self.camera.mirror_trial not in MIRROR_TRIALS:
            raise UsageError(
                f"camera.mirror_trial {self.camera.mirror_trial!r} must be one of {', '.join(MIRROR_TRIALS)}"
            )
        if self.max_frames is not None and self.max_frames < 1:
            raise UsageError("max_frames must be at least 1")
        if self.schedule_frames < 0:
            raise UsageError("schedule_frames must be 0 (off) or a number of frames")
        if self.pose_prior.kind not in POSE_PRIORS or not self.pose_prior.min_std_deg > 0:
            raise UsageError(
                f"pose_prior: kind {self.pose_prior.kind!r} must be one of {', '.join(POSE_PRIORS)} "
                "and min_std_deg positive"
            )
        for f in dataclasses.fields(self.weights):
            v = getattr(self.weights, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 <= v < math.inf:
                raise UsageError(
                    f"weights.{f.name} {v!r} must be a non-negative number", hint="0 turns a term off"
                )
        if not 0 <= self.pose_prior.limit_margin_deg <= 180:
            raise UsageError(
                f"pose_prior.limit_margin_deg {self.pose_prior.limit_margin_deg} must be in [0, 180]"
            )
        if not 0 < self.weights.smooth_until <= 1:
            raise UsageError(
                f"weights.smooth_until {self.weights.smooth_until} must be in (0, 1]",
                hint="a fraction of stage 2's iterations",
            )
        if self.trials.candidates < 1 or self.trials.iters < 0 or not 0 <= self.trials.margin < 1:
            raise UsageError(
                "trials: candidates >= 1, iters >= 0 and 0 <= margin < 1 are required",
                hint="e.g. --candidates 3",
            )
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
    return FitConfig(
        preset="quality",
        fit_size=160,
        soft_sigma=0.05,
        hidden=128,
        camera=CameraConfig(azimuths=16, elevations=[-20.0, 0.0, 20.0, 40.0], search_frames=4),
        stage1=StageConfig(iters=100, lr=5e-2, lr_shape=5e-2, batch=32, renderer="soft", lr_final=0.1),
        stage2=StageConfig(iters=2400, lr=3e-2, lr_shape=1e-3, batch=12, lr_final=0.05, lr_joints_given=1e-2),
    )


PRESETS = {"fast": _fast, "quality": _quality}


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
