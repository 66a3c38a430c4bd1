"""Orchestration of one fit: targets, camera search, stage 1, stage 2, with checkpoints.

`fit_video` is the library entry point (the CLI adds the store, the template choice, outputs and
a rich progress display). A ``Reporter`` receives stage starts and per-step losses; a
``checkpoint`` callable receives a resumable state every ``checkpoint_every`` steps and when the
run is interrupted (Ctrl-C raises ``KeyboardInterrupt`` through here after the state is saved).
"""

from __future__ import annotations

import copy
import dataclasses
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import torch

from ..asset import RiggedAsset
from ..errors import InputError, UsageError
from ..geometry import silhouette_iou
from ..rig.priors import find_symmetry_plane
from .camera_init import CameraInit, camera_follow, initialise_camera, placed_at_depth
from .config import FitConfig
from .depth_mirror import depth_mirror, view_elevation
from .inputs import FitVideo, MaskWindow, crop_box, fit_resolution, resample_flow, resample_masks
from .losses import MaskTargets
from .photometric import colour_targets
from .pose_prior import clip_joint_limits, clip_pose_stats, motion_sequence_prior
from .scene import FitScene
from .stages import StageRunner, Targets, TermLog, make_optimizer, mask_iou, stage_config

STATE_VERSION = 2


class Reporter(Protocol):
    def stage(self, name: str, total: int, done: int = 0) -> None: ...
    def step(self, terms: dict[str, float]) -> None: ...
    def message(self, text: str) -> None: ...


class _Silent:
    def stage(self, name: str, total: int, done: int = 0) -> None:
        pass

    def step(self, terms: dict[str, float]) -> None:
        pass

    def message(self, text: str) -> None:
        pass


@dataclass
class FitResult:
    """scene: the fitted `FitScene` (fit resolution); scale: fit pixels per input pixel; history:
    per stage, a list of loss-term dicts per step; timings in seconds; iou (T,) per-frame mask IoU
    at the input resolution (NaN where the mask is empty); paused: with `fit_video`'s ``pause_at``,
    the state to continue from; search: the first window's camera search (`_search_record`), kept
    in the paused state so a fit at another distance rule need not search again."""

    scene: FitScene
    video: FitVideo
    template: RiggedAsset
    config: FitConfig
    camera_init: dict[str, Any]
    scale: float
    history: dict[str, list[dict[str, float]]] = field(default_factory=dict)
    timings: dict[str, float] = field(default_factory=dict)
    iou: np.ndarray | None = None
    paused: dict[str, Any] | None = None  # resume state where ``pause_at`` stopped stage 2
    search: dict[str, Any] | None = None

    def input_camera(self):
        """The fitted camera at the input resolution (one `Camera`)."""
        from ..render.camera import Camera

        cam = self.scene.camera(1)
        H, W = self.video.size
        k = cam.intrinsics.detach().clone()
        k[:, 0:2] = k[:, 0:2] / self.scale
        k[:, 2] = W / 2.0
        k[:, 3] = H / 2.0
        return Camera(k, cam.rotation.detach(), cam.translation.detach(), H, W)


def check_template(template: RiggedAsset) -> None:
    """Refuse templates the fit cannot use, with a clear reason."""
    if template.num_faces < 4 or template.num_vertices < 4:
        raise InputError(f"template {template.name!r} has too few faces to fit a silhouette")
    if template.num_joints < 1:
        raise InputError(
            f"template {template.name!r} has no skeleton",
            hint="pick a rigged template (see `zooctl bank list`)",
        )


def check_device(device: str) -> None:
    """Refuse a CUDA device PyTorch cannot see, with a clear reason."""
    if device.startswith("cuda") and not torch.cuda.is_available():
        raise UsageError(
            "--device cuda was asked for, but PyTorch sees no CUDA device", hint="use --device cpu"
        )


def fit_video(
    video: FitVideo,
    template: RiggedAsset,
    cfg: FitConfig,
    reporter: Reporter | None = None,
    checkpoint: Callable[[dict[str, Any]], None] | None = None,
    resume: dict[str, Any] | None = None,
    pause_at: int | None = None,
    start: str = "search",
    length: float = 1.0,
    found: dict[str, Any] | None = None,
) -> FitResult:
    """Fit ``template`` to ``video`` (see the module docstring). Deterministic for a given seed.

    A clip longer than ``cfg.window_frames`` is fitted in windows (`FitConfig.windows`): the
    first exactly as a clip of its frames alone (its own crop, camera search and body), each
    later one in its own crop with the body and the camera held, starting from the frames
    before it; the result holds the whole clip.

    ``pause_at``: stop after that many stage-2 iterations (of the configured schedule, so the
    learning rates are those of the full fit) and return with ``result.paused`` set; fitting on
    from it with ``resume=result.paused`` gives what one uninterrupted fit gives. ``start``:
    ``search`` (the camera search's start), ``mirror`` (its depth mirror, `zooctl.fit.view_trial`)
    or ``turned`` (the search's best view at least 90 degrees of azimuth from its start).
    ``length``: the template's body made that much longer first (its model's ``lengthen``; the
    template trials' longer body). ``found``: a paused state's ``search`` (a fit of this template
    and video paused, at another ``camera.depth`` perhaps): its start placed at this config's
    distances (`placed_at_depth`) instead of searching again, where it was searched for the same
    body, camera settings and start; else the search runs. All concern the first window."""
    rep = reporter or _Silent()
    if start not in ("search", "mirror", "turned"):
        raise ValueError(f"start must be search, mirror or turned, not {start!r}")
    cfg.validate()
    check_template(template)
    check_device(cfg.device)
    video = video.truncated(cfg.max_frames).check()
    spans = cfg.windows(video.num_frames)
    if len(spans) == 1:
        return _fit_window(
            video, template, cfg, rep, checkpoint, resume, pause_at, start, length=length, found=found
        )
    if resume is not None and resume.get("window", 0) > 0:
        _check_version(resume)
        result, next_window = _resumed_whole(resume, video, template, cfg), int(resume["window"])
    else:
        # One first window per video, so the template trials' fits share its cache (its flow targets).
        head = video.cache.setdefault(("window", spans[0]), video.part(*spans[0]))
        first = _fit_window(
            head, template, cfg, rep, checkpoint, resume, pause_at, start, length=length, found=found
        )
        if first.paused is not None:
            return first
        result, next_window = _whole(first, video), 1
    t = time.perf_counter()
    for window in range(next_window, len(spans)):
        _fit_later_window(result, spans, window, rep, checkpoint)
    t2 = time.perf_counter()
    result.iou = input_mask_iou(result)
    result.timings["evaluate"] = result.timings.get("evaluate", 0.0) + time.perf_counter() - t2
    result.timings["later_windows"] = result.timings.get("later_windows", 0.0) + t2 - t
    return result


def _fit_window(
    video: FitVideo,
    template: RiggedAsset,
    cfg: FitConfig,
    rep: Reporter,
    checkpoint: Callable[[dict[str, Any]], None] | None,
    resume: dict[str, Any] | None,
    pause_at: int | None,
    start: str,
    *,
    length: float = 1.0,
    held: _Held | None = None,
    found: dict[str, Any] | None = None,
) -> FitResult:
    """One window's fit: a whole clip's, or (``held``) a later window's of a long clip."""
    torch.manual_seed(cfg.seed)
    timings: dict[str, float] = dict(resume.get("timings", {})) if resume else {}
    t0 = time.perf_counter()
    T, H, W = video.masks.shape
    box = crop_box(video.masks)
    x0, y0, x1, y1 = box
    h, w, s = fit_resolution(y1 - y0, x1 - x0, cfg.fit_size)
    s = h / (y1 - y0)
    crop = MaskWindow(video.masks, box)
    coverage = resample_masks(crop, h, w)
    dev = cfg.device
    mt = MaskTargets.build(coverage, seed=cfg.seed, device=dev)
    flow = (
        resample_flow(video, h, w, box) if (cfg.ablation.flow and cfg.ablation.optimise and T > 1) else None
    )
    targets = Targets(
        mt,
        None if flow is None else torch.as_tensor(flow[0], device=dev),
        None if flow is None else torch.as_tensor(flow[1], device=dev),
        _colour_targets(video, box, h, w, dev)
        if cfg.weights.photometric > 0 and cfg.ablation.optimise
        else None,
    )
    timings.setdefault("targets", time.perf_counter() - t0)
    focal_given = cfg.camera.focal is not None or video.intrinsics is not None
    if cfg.camera.focal is None and video.intrinsics is not None:
        # a copy: the caller's config stays as given (a batch's next video must not inherit it)
        camera = dataclasses.replace(cfg.camera, focal=float(video.intrinsics[0]))
        cfg = dataclasses.replace(cfg, camera=camera)
    scene = new_scene(template, cfg, T, h, w, ((W / 2 - x0) * s, (H / 2 - y0) * s))
    if length != 1.0 and held is None and resume is None:  # a resumed state holds its lengths
        lengthen = getattr(scene.model, "lengthen", None)  # optional (`zooctl.rig.base`)
        if lengthen is None:
            rep.message(f"the {cfg.articulation} articulation model cannot lengthen a body: fitted as it is")
        else:
            lengthen(length)
    if cfg.pose_prior.kind == "clips":
        scene.clip_stats = clip_pose_stats(template, cfg.pose_prior.min_std_deg, dev)
    elif cfg.pose_prior.kind == "motion":
        scene.sequence_prior = motion_sequence_prior(cfg.pose_prior.motion, template, video.fps, dev)
    if cfg.weights.joint_limits > 0:
        scene.joint_limits = clip_joint_limits(template, cfg.pose_prior.limit_margin_deg, dev)
        if scene.joint_limits is None and held is None:
            rep.message(
                f"{template.name} has no clips to learn joint limits from: weights.joint_limits does nothing"
            )
    if held is not None:
        motion, motion_used = _camera_motion(video, cfg)
        held.place(
            scene, crop, cfg, s, (W / 2 - x0, H / 2 - y0), H, motion.rotations if motion_used else None
        )
        cam_info: dict[str, Any] = {}
        history: dict[str, list[dict[str, float]]] = {"stage1": [], "stage2": []}
        start_stage, start_iter, opt_state, colours = 1, 0, None, None
        search = None
    elif resume is None:
        t1 = time.perf_counter()
        motion, motion_used = _camera_motion(video, cfg)
        rest = scene.rest_vertices().cpu().numpy()
        key = _search_key(cfg, rest, start, motion_used)
        init = _found_start(found, key, rest, cfg.camera.depth)
        reused = init is not None
        if init is None:
            rep.message("searching the camera and viewpoint")
            init = initialise_camera(
                rest,
                template.faces,
                crop,
                cfg.camera,
                s,
                cfg.seed,
                (W / 2 - x0, H / 2 - y0),
                H,
                video.camera_rotations,
                turned=start == "turned",
                camera_motion=motion.rotations if motion_used else None,
            )
        search = _search_record(init, key, cfg.camera.depth)
        elevation = view_elevation(init.root_rotation)
        if start == "mirror":
            init = depth_mirror(init, rest, *find_symmetry_plane(rest)[:2])
        with torch.no_grad():
            scene.log_focal.fill_(float(np.log(init.focal)))
            scene.root_rotation.copy_(torch.as_tensor(init.root_rotation, dtype=torch.float32))
            scene.root_translation.copy_(torch.as_tensor(init.root_translation, dtype=torch.float32))
        timings["camera"] = time.perf_counter() - t1
        cam_info = _camera_info(init, s) | {"elevation_deg": elevation}
        if reused:
            cam_info["search_reused_from_depth"] = found["depth"]
        if motion is not None:
            cam_info["motion"] = {"from": "background", "used": motion_used} | motion.summary()
        history = {"stage1": [], "stage2": []}
        start_stage, start_iter, opt_state, colours = 1, 0, None, None
    else:
        _check_version(resume)
        scene.load_state_dict(resume["scene"])
        cam_info = resume["camera_init"]
        history = resume["history"]
        start_stage, start_iter, opt_state = resume["stage"], resume["iteration"], resume.get("optimizer")
        colours = resume.get("colours")
        search = resume.get("search")
    result = FitResult(scene, video, template, cfg, cam_info, s, history, timings, search=search)
    if cfg.ablation.optimise:
        span = (0, T) if held is None else (held.anchors, T)
        for stage in (1, 2):
            if stage < start_stage:
                continue
            _run_stage(
                result,
                targets,
                stage,
                span,
                held,
                start_iter if stage == start_stage else 0,
                not focal_given and held is None,
                rep,
                checkpoint,
                opt_state if stage == start_stage else None,
                pause_at if stage == 2 else None,
                colours if stage == start_stage else None,
            )
    if held is None:
        t2 = time.perf_counter()
        result.iou = input_mask_iou(result)
        timings["evaluate"] = time.perf_counter() - t2
    return result


def _search_key(cfg: FitConfig, rest: np.ndarray, start: str, motion_used: bool) -> dict[str, Any]:
    """What a camera search's result depends on, but the distance rule (`fit_video`'s ``found``):
    the camera settings, the seed, the start asked for, whether the camera's turn was read, and
    the body searched (its rest box)."""
    camera = {k: v for k, v in dataclasses.asdict(cfg.camera).items() if k != "depth"}
    box = [float(x) for x in np.concatenate([rest.min(0), rest.max(0)])]
    return {
        "camera": camera,
        "seed": cfg.seed,
        "turned": start == "turned",
        "motion": motion_used,
        "body": box,
    }


def _search_record(init: CameraInit, key: dict[str, Any], depth: str) -> dict[str, Any]:
    """The camera search's start (before any depth mirror), its key and the distance rule that
    placed it: a paused state's ``search``."""
    return {"key": key, "depth": depth} | dataclasses.asdict(init)


def _found_start(
    found: dict[str, Any] | None, key: dict[str, Any], rest: np.ndarray, depth: str
) -> CameraInit | None:
    """``found`` (`_search_record`; from a checkpoint its arrays are tensors) placed at ``depth``
    where it was searched under ``key``, else None (search again)."""
    if found is None or found.get("key") != key:
        return None
    init = CameraInit(
        float(found["focal"]),
        np.asarray(found["root_rotation"], np.float64),
        np.asarray(found["root_translation"], np.float64),
        list(found["candidates"]),
        float(found["iou"]),
        [float(x) for x in found["keyframe_iou"]],
        [int(t) for t in found["present"]],
    )
    return placed_at_depth(init, rest, str(found["depth"]), depth)


def _colour_targets(video: FitVideo, box: tuple[int, int, int, int], h: int, w: int, device: str):
    """`colour_targets`, kept in ``video.cache`` as the flow is: the template trials' fits of a
    video read the same frames (the losses only read them)."""
    key = ("colours", h, w, *box, str(device))
    if key not in video.cache:
        video.cache[key] = colour_targets(video.frames, box, h, w, device)
    return video.cache[key]


def trial_camera_turn(video: FitVideo, cfg: FitConfig) -> np.ndarray | None:
    """(T, 3, 3) each frame's camera turn in the fit's axes (`camera_follow`, frame 0 the
    reference) over the frames a template trial fits (the first window of a long clip): from the
    given camera rotations, else read from the background (`_camera_motion`, whatever the camera
    search does with it) unless ``camera.motion`` is ``none``. None where the camera turns less
    than ``camera.track_step`` over them: a camera at rest tells nothing of the body's turn."""
    video = video.truncated(cfg.max_frames)
    spans = cfg.windows(video.num_frames)
    if len(spans) > 1:
        video = video.cache.setdefault(("window", spans[0]), video.part(*spans[0]))
    if video.camera_rotations is not None:
        return camera_follow(np.asarray(video.camera_rotations, np.float64), 0)
    if cfg.camera.motion == "none":
        return None
    motion, used = _camera_motion(video, cfg, always=True)
    return camera_follow(motion.rotations, 0) if used else None


def _camera_motion(video: FitVideo, cfg: FitConfig, always: bool = False) -> tuple[Any, bool]:
    """(the camera's turn read from the background, `zooctl.video.camera_motion.background_motion`,
    or None; whether it is used). Read when ``camera.motion`` is ``background`` (or ``always``)
    and the camera's rotations are not known, at the fit's focal (a normal lens when the camera
    search is to choose it), and kept in ``video.cache`` for the template trials' fits. Used when
    the camera turns at least the tracker's step over the video: less tells no start from another,
    and is taken as at rest."""
    if (cfg.camera.motion != "background" and not always) or video.camera_rotations is not None:
        return None, False
    H, W = video.size
    focal = float(cfg.camera.focal) if cfg.camera.focal is not None else math.hypot(W, H)
    key = ("camera_motion", round(focal, 3))
    if key not in video.cache:
        from ..video.camera_motion import background_motion

        video.cache[key] = background_motion(video.frames, video.masks, focal, seed=cfg.seed)
    motion = video.cache[key]
    return motion, motion.span_deg() >= cfg.camera.track_step


def new_scene(
    template: RiggedAsset, cfg: FitConfig, num_frames: int, h: int, w: int, principal: tuple[float, float]
) -> FitScene:
    """A `FitScene` of ``num_frames`` frames in (h, w) fit images as ``cfg`` sets it up."""
    # Articulation plugins need not know the option (`get_articulation_model` leaves it out).
    options = {"share_seams": cfg.ablation.share_seams, "girth": cfg.ablation.girth}
    return FitScene(
        template,
        num_frames,
        h,
        w,
        focal=1.0,
        stretch=cfg.ablation.stretch,
        displacement=cfg.ablation.displacement,
        hidden=cfg.hidden,
        device=cfg.device,
        principal=principal,
        articulation=cfg.articulation,
        **options,
    )


def _check_version(state: dict[str, Any]) -> None:
    if state.get("version") != STATE_VERSION:
        raise InputError(
            "the saved fit state is from another zooctl version", hint="start the fit again without --resume"
        )


_PER_FRAME = ("rotations", "root_rotation", "root_translation")


def _whole(first: FitResult, video: FitVideo) -> FitResult:
    """The result of a long clip's fit holding its first window's: a scene of all its frames at
    the first window's fit resolution (the later windows' frames filled as they are fitted)."""
    sc = first.scene
    n = sc.num_frames
    scene = new_scene(first.template, first.config, video.num_frames, sc.height, sc.width, sc.principal)
    state = sc.state_dict()
    with torch.no_grad():
        for k, v in scene.state_dict().items():
            v[:n].copy_(state[k]) if k in _PER_FRAME else v.copy_(state[k])
    history = {k: list(v) for k, v in first.history.items()}
    return FitResult(
        scene,
        video,
        first.template,
        first.config,
        first.camera_init,
        first.scale,
        history,
        dict(first.timings),
    )


def _resumed_whole(
    state: dict[str, Any], video: FitVideo, template: RiggedAsset, cfg: FitConfig
) -> FitResult:
    g = state["whole"]
    scene = new_scene(template, cfg, video.num_frames, g["height"], g["width"], tuple(g["principal"]))
    scene.load_state_dict(state["scene"])
    return FitResult(
        scene,
        video,
        template,
        cfg,
        state["camera_init"],
        g["scale"],
        state["history"],
        dict(state["timings"]),
    )


@dataclass
class _Held:
    """What a later window of a long clip holds: the whole clip's result so far, its span in the
    clip, and how many frames before it (already fitted) it starts with."""

    whole: FitResult
    span: tuple[int, int]
    anchors: int

    def place(
        self,
        scene: FitScene,
        crop: MaskWindow,
        cfg: FitConfig,
        s: float,
        principal: tuple[float, float],
        H: int,
        camera_motion: np.ndarray | None = None,
    ) -> None:
        """The window's ``scene`` (its first `anchors` frames the fitted ones before it): the
        body and the focal from the whole clip's fit, the anchors' pose and root, the root
        tracked on from the last anchor's (carried by ``camera_motion``, the window's camera
        turn, when given) and each frame aligned to its mask, the joints at the last anchor's
        pose."""
        from ..geometry import quat_to_matrix

        whole, a, lo = self.whole.scene, self.anchors, self.span[0]
        focal_px = float(whole.focal().detach()) / self.whole.scale  # input pixels
        body = {k: v for k, v in whole.state_dict().items() if k not in _PER_FRAME}
        scene.load_state_dict(body, strict=False)
        past = slice(lo - a, lo)
        q = whole.root_rotation[lo - a].detach().cpu().numpy().astype(np.float64)
        start = quat_to_matrix(q / np.linalg.norm(q))
        camera = dataclasses.replace(cfg.camera, focal=focal_px)
        rest = (scene.rest_vertices() * scene.model.global_scale()).detach().cpu().numpy()
        init = initialise_camera(
            rest,
            self.whole.template.faces,
            crop,
            camera,
            s,
            cfg.seed,
            principal,
            H,
            None,
            start=start,
            camera_motion=camera_motion,
        )
        with torch.no_grad():
            scene.log_focal.fill_(float(np.log(focal_px * s)))
            scene.root_rotation.copy_(torch.as_tensor(init.root_rotation, dtype=torch.float32))
            scene.root_translation.copy_(torch.as_tensor(init.root_translation, dtype=torch.float32))
            for k in _PER_FRAME:
                getattr(scene, k)[:a] = getattr(whole, k)[past]
            scene.rotations[a:] = whole.rotations[lo - 1]


def _fit_later_window(
    result: FitResult,
    spans: list[tuple[int, int]],
    window: int,
    rep: Reporter,
    checkpoint: Callable[[dict[str, Any]], None] | None,
) -> None:
    """Fit window ``window`` of a long clip into ``result`` (the whole clip's)."""
    lo, hi = spans[window]
    a = min(2, lo)  # the frames before it that its sequence terms see (one of them its steps)
    state = {
        "version": STATE_VERSION,
        "window": window,
        "stage": 1,
        "iteration": 0,
        "scene": result.scene.state_dict(),
        "whole": {
            "height": result.scene.height,
            "width": result.scene.width,
            "principal": list(result.scene.principal),
            "scale": result.scale,
        },
        "history": result.history,
        "camera_init": result.camera_init,
        "config": result.config.to_dict(),
        "timings": result.timings,
    }
    keep = None if checkpoint is None else (lambda _: checkpoint(state))  # resume: from the window's start
    if keep is not None:
        keep(None)
    held = _Held(result, (lo, hi), a)
    part = _fit_window(
        result.video.part(lo - a, hi),
        result.template,
        result.config,
        rep,
        keep,
        None,
        None,
        "search",
        held=held,
    )
    with torch.no_grad():
        for k in _PER_FRAME:
            getattr(result.scene, k)[lo:hi] = getattr(part.scene, k)[a:]
    for k, v in part.history.items():
        result.history[k].extend(v)


def _camera_info(init: CameraInit, s: float) -> dict[str, Any]:
    return {
        "focal_px": init.focal / s,
        "search_iou": init.iou,
        "keyframe_iou": init.keyframe_iou,
        "candidates": [dict(c, focal=c["focal"]) for c in init.candidates],
    }


def _run_stage(
    result: FitResult,
    targets: Targets,
    stage: int,
    span: tuple[int, int],
    held: _Held | None,
    first: int,
    learn_focal: bool,
    rep: Reporter,
    checkpoint,
    opt_state,
    pause_at: int | None = None,
    colours=None,
) -> None:
    cfg, scene = result.config, result.scene
    st = stage_config(cfg, stage, span[1] - span[0])
    last = st.iters if pause_at is None else min(st.iters, max(pause_at, first))
    runner = StageRunner(scene, targets, cfg, stage, span, colours)
    opt = make_optimizer(scene, cfg, stage, learn_focal, shared=held is None)
    if runner.colours is not None:
        opt.add_param_group({"params": [runner.colours], "lr": st.lr})
    base_lr = [g["lr"] for g in opt.param_groups]
    if opt_state is not None:
        opt.load_state_dict(opt_state)
    key = f"stage{stage}"
    rep.stage(key if held is None else f"{key}, frames {held.span[0]}-{held.span[1] - 1}", last, first)
    t = time.perf_counter()
    done = first
    log = TermLog(result.history[key], rep.step)

    def state(next_iter: int) -> dict[str, Any]:
        log.flush()
        timings = dict(result.timings)
        timings[key] = timings.get(key, 0.0) + time.perf_counter() - t
        return (
            {
                "version": STATE_VERSION,
                "stage": stage,
                "iteration": next_iter,
                "scene": scene.state_dict(),
                "optimizer": opt.state_dict(),
                "history": result.history,
                "camera_init": result.camera_init,
                "config": cfg.to_dict(),
                "timings": timings,
            }
            | ({} if runner.colours is None else {"colours": runner.colours.detach().clone()})
            | ({} if result.search is None else {"search": result.search})
        )

    try:
        # Skip the runner's random windows already drawn before an interruption (resume = same run).
        for _ in range(first):
            runner.window()
        for it in range(first, last):
            factor = lr_factor(it, st.iters, st.lr_final)
            for g, lr in zip(opt.param_groups, base_lr, strict=True):
                g["lr"] = lr * factor
            log.add(runner.step(opt, it))
            done = it + 1
            if checkpoint is not None and cfg.checkpoint_every and (it + 1) % cfg.checkpoint_every == 0:
                checkpoint(state(it + 1))
    except KeyboardInterrupt:
        if checkpoint is not None:
            checkpoint(state(done))
        raise
    log.flush()
    left_out = runner.pair_overflows()
    if left_out:
        rep.message(f"{key}: {left_out} renders on the device left pixels out before their pair budget grew")
    if pause_at is not None:
        result.paused = copy.deepcopy(state(last))
    result.timings[key] = result.timings.get(key, 0.0) + time.perf_counter() - t


def lr_factor(it: int, iters: int, final: float) -> float:
    """Cosine decay of the learning rates from 1 at step 0 to ``final`` at the last step."""
    if final >= 1.0 or iters <= 1:
        return 1.0
    return final + (1.0 - final) * 0.5 * (1.0 + np.cos(np.pi * it / (iters - 1)))


@torch.no_grad()
def input_mask_iou(result: FitResult, masks: np.ndarray | None = None) -> np.ndarray:
    """(T,) IoU of the fitted silhouettes with the input masks at the input resolution.

    ``masks`` (T, H, W) bool replaces the masks the fit used, e.g. ground truth for a fit made
    from automatic masks.
    """
    from ..render.raster import rasterize

    scene = result.scene
    masks = result.video.masks if masks is None else masks
    cam = result.input_camera().to(scene.rotations.device)
    out = []
    B = 8
    for s in range(0, scene.num_frames, B):
        idx = torch.arange(s, min(s + B, scene.num_frames), device=scene.rotations.device)
        sil = rasterize(scene.pose(idx).vertices, scene.faces, cam.expand(len(idx))).mask.cpu().numpy()
        out.append(silhouette_iou(sil, masks[idx.cpu().numpy()]))
    return np.concatenate(out)


__all__ = ["FitResult", "fit_video", "input_mask_iou", "mask_iou"]
