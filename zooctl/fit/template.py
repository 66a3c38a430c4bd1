"""Choosing the template: the bank asset named by ``--template``, else template retrieval.

Retrieval is `zooctl.retrieval` (CASA's embedding search over rendered views of every bank asset):
the masked crops of a few frames are embedded with the enabled embedders and the bank ranked.
`try_candidates` then gives the best few a short fit each and keeps the one that scores best
(``FitConfig.trials``, `trial_score`): the embeddings alone often rank the wrong body plan first
(BENCHMARKS.md, Retrieval), and the fit's own mask IoU is a direct check, weighed with what the
classifier sees, what the template's surface had to move to fit and, where the camera turns
round the animal, how far the body had to turn in the world to follow it (``trials.margin`` lets
retrieval's order settle near-ties). Where retrieval's first candidate is far ahead of the rest
(``trials.sure``), it is fitted without trials: a short fit's silhouettes cannot overrule it. A
trial is the beginning of the full fit, paused: the winner's fit goes on from its trial, so the
trials cost only the losers' fits.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import numpy as np

from ..asset import RiggedAsset
from ..errors import UsageError
from .view_trial import TRIAL_WORLD_SPREAD_WEIGHT, mirror_wanted, trial_world_spread

if TYPE_CHECKING:
    from ..store.bank import Bank
    from .config import FitConfig
    from .inputs import FitVideo
    from .run import Reporter


def retrieve(
    bank: Bank,
    frames: np.ndarray,
    masks: np.ndarray,
    exclude: set[str] | None = None,
    top: int = 5,
    device: str = "cpu",
    trials: int = 3,
) -> list[dict[str, Any]]:
    """Ranked candidates ``[{"name", "score", "distances"}]`` (best first, lower score is better).

    The best-scoring asset of the animal's family (its label shares the family, or the species,
    of what the video shows: `zooctl.retrieval.semantic`) is moved up to the ``trials``-th place
    when it ranks lower, so the template trials always try it. Labelled candidates carry their
    ``label`` and, where it shares a taxon with the video's animal, ``shares`` ("family Canidae")."""
    try:
        from ..retrieval.index import enabled_embedders
        from ..retrieval.query import QueryFrames, classifier_crops, crops_from_frames
        from ..retrieval.search import embed_query, score_bank
    except ImportError as exc:  # pragma: no cover - retrieval ships with zooctl
        raise UsageError(
            "template retrieval is not available in this installation", hint="pass --template NAME"
        ) from exc
    images, crop_masks, chosen = crops_from_frames(frames, masks, 8, 224)
    query = QueryFrames(images, crop_masks, chosen, "fit")
    query.class_images = classifier_crops(frames, masks, chosen, 224)
    emb, _ = embed_query(query, enabled_embedders(), device)
    res = score_bank(bank, emb, query.identities, query.classes, exclude=exclude)
    if not res.matches:
        raise UsageError(
            "template retrieval found no candidate in the bank",
            hint="seed or fill the bank (`zooctl bank seed`, `zooctl bank add`), run `zooctl bank reindex`, or pass --template NAME",
        )
    ranked = promote_kin(res.matches, trials)
    out = []
    for m in ranked[: max(top, trials)]:
        c = {
            "name": m.name,
            "score": float(m.score),
            "distances": {k: float(v) for k, v in m.distances.items()},
        }
        if m.label is not None:
            c["label"] = m.label
        if m.taxon:
            c["shares"] = f"{m.taxon[0]} {m.taxon[1]}"  # with what the video shows
        if m.semantic is not None:
            c["semantic"] = round(float(m.semantic), 4)
        out.append(c)
    if len(out) > 1:
        out[0]["lead"] = round(retrieval_lead(out), 4)
    return out


def retrieval_lead(candidates: list[dict[str, Any]]) -> float:
    """How much better (lower) the first candidate's score is than the best of the others':
    what ``trials.sure`` is compared with (0 where there is no other; negative where the
    family's best was moved first from behind it, `promote_kin` with one trial)."""
    others = [float(c["score"]) for c in candidates[1:]]
    return min(others) - float(candidates[0]["score"]) if others else 0.0


def promote_kin(matches: list[Any], trials: int) -> list[Any]:
    """Search matches in order, with the best one of the video's family (its ``taxon`` shares the
    species or the family) moved up to place ``trials`` when it ranks below it."""
    ranked = list(matches)
    kin = next((i for i, m in enumerate(ranked) if m.taxon and m.taxon[0] in ("species", "family")), None)
    if kin is not None and kin >= trials > 0:
        ranked.insert(trials - 1, ranked.pop(kin))
    return ranked


def check_bank_ready(bank: Bank, name: str | None) -> None:
    """Refuse a fit the bank cannot serve before any video work (decoding, flow and masks take
    minutes on a long clip): ``NotFoundError`` for a named template the bank lacks, `UsageError`
    when retrieval would have nothing to retrieve."""
    if name is not None:
        bank.summary(name)
    elif len(bank) == 0:
        raise UsageError(
            "the bank is empty: there is no template to fit",
            hint="run `zooctl bank seed`, or add assets with `zooctl bank add`",
        )


def choose_template(
    bank: Bank,
    name: str | None,
    frames: np.ndarray,
    masks: np.ndarray,
    exclude: set[str] | None = None,
    device: str = "cpu",
    trials: int = 3,
) -> tuple[RiggedAsset, list[dict[str, Any]]]:
    """(template asset, retrieval candidates) - candidates are empty when ``name`` was given.
    ``trials``: how many candidates the template trials try (`retrieve`)."""
    if name is not None:
        return bank.get(name), []
    check_bank_ready(bank, None)
    cands = retrieve(bank, frames, masks, exclude=exclude, device=device, trials=trials)
    return bank.get(cands[0]["name"]), cands


def select_template(
    bank: Bank,
    name: str | None,
    video: FitVideo,
    cfg: FitConfig,
    exclude: set[str] | None = None,
    reporter: Reporter | None = None,
) -> tuple[RiggedAsset, list[dict[str, Any]], dict[str, Any] | None, float | None]:
    """`choose_template`, then the template trials when the template was retrieved and the config
    asks for them: (template, candidates, the winning trial's state to continue from or None,
    seconds spent in the trials or None). No trials where retrieval's first candidate leads the
    others by ``cfg.trials.sure`` or more (`retrieval_lead`)."""
    import time

    asset, candidates = choose_template(
        bank,
        name,
        video.frames,
        video.masks,
        exclude=exclude,
        device=cfg.device,
        trials=cfg.trials.candidates,
    )
    if len(candidates) < 2 or cfg.trials.candidates < 2 or not cfg.ablation.optimise:
        return asset, candidates, None, None
    sure, lead = cfg.trials.sure, retrieval_lead(candidates)
    if sure is not None and lead >= sure:
        if reporter is not None:
            reporter.message(
                f"template {asset.name}: retrieval is sure of it (ahead by {lead:.2f}, "
                f"trials.sure {sure:g}); no template trials"
            )
        return asset, candidates, None, None
    t = time.perf_counter()
    asset, candidates, state = try_candidates(bank, video, candidates, cfg, reporter)
    return asset, candidates, state, time.perf_counter() - t


def try_candidates(
    bank: Bank,
    video: FitVideo,
    candidates: list[dict[str, Any]],
    cfg: FitConfig,
    reporter: Reporter | None = None,
) -> tuple[RiggedAsset, list[dict[str, Any]], dict[str, Any] | None]:
    """Short-fit the first ``cfg.trials.candidates`` retrieval candidates; (best template, the
    candidates with ``trial_iou`` added to those tried, the best trial's fit state or None).

    A trial is the start of the full fit (camera search, stage 1 and the first ``cfg.trials.iters``
    stage-2 iterations of the configured schedule), paused, from the search's start (or its depth
    mirror with ``camera.mirror_trial`` ``always``: `zooctl.fit.view_trial`); the state returned continues the
    winner's fit exactly where its trial stopped (`fit_video`'s ``resume``). The winner is
    `pick_trial`'s (``cfg.trials.margin``). With ``cfg.trials.prune_at`` every trial first stops
    there, and only those `kept_trials` keeps (``cfg.trials.prune_margin``) go on to
    ``cfg.trials.iters`` and compete; the others' candidates get ``pruned_at`` beside the trial IoU
    they stopped at. A depth-mirror check then compares at the checkpoint.

    Where the camera turns round the animal (`trial_camera_turn` reads it) and ``cfg.trials.carried``,
    each candidate is tried twice, from the search's start and from one carried by the camera's
    turn (``camera.motion`` background), and its trial is the start of the higher `trial_score`
    (``trial_start`` and ``other_start_score`` in its record; `winner_config` carries the rest of
    the winner's fit the same way). The two are compared at ``cfg.trials.carried_at`` (or at
    ``prune_at`` where that is earlier), and only the better goes on to ``cfg.trials.iters``.

    The trials fit the shape at ``cfg.trials.lr_shape`` and start from ``cfg.trials.depth``
    (`FitConfig.for_trials`); the winner's fit goes on from its trial's state at ``cfg``'s own
    rate, from its trial run again at ``cfg.camera.depth`` where the two differ (`_winner_again`)."""
    from .run import trial_camera_turn
    from .trial_pool import Trial, run_trials

    fit_depth = cfg.camera.depth
    cfg = cfg.for_trials()
    tried = candidates[: cfg.trials.candidates]
    if len(tried) < 2:
        return bank.get(candidates[0]["name"]), candidates, None
    semantic = [float(c.get("semantic") or 0.0) for c in tried]
    prune_at = cfg.trials.prune_at
    mirror = mirror_wanted(cfg, template_given=False)
    assets = [bank.get(c["name"]) for c in tried]
    turn = trial_camera_turn(video, cfg)
    # Each run: (candidate, its start's camera.motion or None for the config's own).
    runs: list[tuple[int, str | None]] = [(i, None) for i in range(len(tried))]
    if carried_start_wanted(video, cfg, turn):
        runs += [(i, "background") for i in range(len(tried))]
    # The trials pause once: where the candidates are pruned, or where each one's two starts are
    # compared (BENCHMARKS.md, "Each candidate from two starts on 78 more videos").
    pauses = [prune_at, cfg.trials.carried_at if len(runs) > len(tried) else None]
    first = min([p for p in pauses if p is not None] + [cfg.trials.iters])
    if reporter is not None:
        reporter.message(
            "trial fits: "
            + ", ".join(a.name for a in assets)
            + (", each also from a start carried by the camera's turn" if len(runs) > len(tried) else "")
        )
    trials = [Trial(assets[i], first, mirror, motion=m) for i, m in runs]
    results = run_trials(video, trials, cfg, reporter)  # retrieval order, the carried starts after
    spread: list[float | None] = [None] * len(runs)

    def measure(k: int) -> None:
        spread[k] = trial_world_spread(results[k].state, turn)

    def score(k: int) -> float:
        i = runs[k][0]
        res = results[k]
        return trial_score(
            res.iou, semantic[i], res.displacement, spread[k], res.consistency, cfg.trials.view_consistency
        )

    def record(i: int, k: int | None = None) -> int:
        """Candidate ``i``'s trial into its record: run ``k``, or the best-scoring of its starts
        (retrieval's search first on a tie). Returns the run's index."""
        ks = [j for j, (c, _) in enumerate(runs) if c == i]
        if k is None:
            k = max(ks, key=lambda j: (score(j), -j))
            tried[i]["view_trial"] = results[k].view
            if len(ks) > 1:
                tried[i]["trial_start"] = "carried" if runs[k][1] is not None else "search"
                tried[i]["other_start_score"] = round(max(score(j) for j in ks if j != k), 4)
        res, cand = results[k], tried[i]
        cand["trial_iou"] = round(res.iou, 4)
        cand["trial_displacement"] = round(res.displacement, 4)
        cand.pop("trial_world_spread_deg", None)
        if spread[k] is not None:
            cand["trial_world_spread_deg"] = round(spread[k], 2)
        cand.pop("trial_view_consistency", None)
        if res.consistency is not None:
            cand["trial_view_consistency"] = round(res.consistency, 4)
        return k

    for k in range(len(runs)):
        measure(k)
    on = [record(i) for i in range(len(tried))]  # each candidate's better start: these go on
    if first < cfg.trials.iters:
        if prune_at is not None:
            on = [on[j] for j in kept_trials([score(k) for k in on], cfg.trials.prune_margin)]
        for i, cand in enumerate(tried):
            if not any(runs[k][0] == i for k in on):
                cand["pruned_at"] = first  # its trial_iou is the one at the checkpoint
        if reporter is not None:
            names = ", ".join(tried[runs[k][0]]["name"] for k in on)
            reporter.message(f"trial fits of {names} go on to {cfg.trials.iters} iterations")
        more = run_trials(
            video,
            [Trial(assets[runs[k][0]], cfg.trials.iters, state=results[k].state) for k in on],
            cfg,
            reporter,
        )
        for k, res in zip(on, more, strict=True):
            results[k] = res
            measure(k)
            record(runs[k][0], k)
    won = on[pick_trial([score(k) for k in on], cfg.trials.margin)]
    win = runs[won][0]
    best, best_state = assets[win], results[won].state
    if cfg.trials.longer != 1.0:
        best_state = (
            _try_longer(
                video, tried[win], best, semantic[win], score(won), mirror, cfg, reporter, turn, runs[won][1]
            )
            or best_state
        )
    if reporter is not None:
        reporter.message(f"template {best.name}: trial mask IoU {results[won].iou:.3f}")
    if cfg.camera.depth != fit_depth:
        best_state = _winner_again(
            video, tried[win], best, mirror, cfg, fit_depth, runs[won][1], reporter, best_state
        )
    if best_state is not None:
        best_state["timings"] = {}  # the trials are timed as a whole by the caller
    return best, candidates, best_state


def carried_start_wanted(video: FitVideo, cfg: FitConfig, turn: np.ndarray | None) -> bool:
    """Whether each candidate is also tried from a start carried by the camera's turn
    (`try_candidates`): ``cfg.trials.carried``, a turn read from the background (``turn``:
    `trial_camera_turn`; not the given camera rotations) and a config that does not carry every
    start already (``camera.motion`` background)."""
    return (
        cfg.trials.carried
        and turn is not None
        and video.camera_rotations is None
        and cfg.camera.motion != "background"
    )


def winner_config(cfg: FitConfig, candidates: list[dict[str, Any]], chosen: str) -> FitConfig:
    """The config the chosen template's fit goes on with: ``camera.motion`` ``background`` where
    its trial started carried by the camera's turn (``trial_start``), so a long clip's later
    windows are carried as its first was; else ``cfg`` itself."""
    if any(c["name"] == chosen and c.get("trial_start") == "carried" for c in candidates):
        return cfg.with_camera_motion("background")
    return cfg


def _try_longer(
    video: FitVideo,
    cand: dict[str, Any],
    asset: RiggedAsset,
    semantic: float,
    score: float,
    mirror: bool,
    cfg: FitConfig,
    reporter: Reporter | None,
    turn: np.ndarray | None = None,
    motion: str | None = None,
) -> dict[str, Any] | None:
    """The winner's trial again with its body ``cfg.trials.longer`` times longer (`fit_video`'s
    ``length``): its paused state where its `trial_score` beats the winner's ``score`` (a tie keeps
    the template's own proportions), else None. ``cand`` gets ``longer_trial_iou``,
    ``longer_trial_displacement`` and, when kept, ``length``. ``motion``: the winner's start's
    ``camera.motion`` (`zooctl.fit.trial_pool.Trial`)."""
    from .trial_pool import Trial, run_trials

    factor = cfg.trials.longer
    if reporter is not None:
        reporter.message(f"trial fit of {asset.name} {factor:g} times longer")
    (res,) = run_trials(
        video, [Trial(asset, cfg.trials.iters, mirror, length=factor, motion=motion)], cfg, reporter
    )
    cand["longer_trial_iou"] = round(res.iou, 4)
    cand["longer_trial_displacement"] = round(res.displacement, 4)
    spread = trial_world_spread(res.state, turn)
    if (
        trial_score(res.iou, semantic, res.displacement, spread, res.consistency, cfg.trials.view_consistency)
        <= score
    ):
        return None
    cand["length"] = factor
    return res.state


def _winner_again(
    video: FitVideo,
    cand: dict[str, Any],
    asset: RiggedAsset,
    mirror: bool,
    cfg: FitConfig,
    depth: str,
    motion: str | None,
    reporter: Reporter | None,
    state: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The winner's trial run again with ``camera.depth`` ``depth`` (the trials ran with
    ``trials.depth``): its start, depth-mirror check, carried start (``motion``) and length as its
    trial's, its camera search the one in its trial's paused ``state`` placed at ``depth``
    (`zooctl.fit.camera_init.placed_at_depth`) where that can be; its paused state, for the fit to
    go on from. ``cand`` gets ``refit_trial_iou``."""
    from .trial_pool import Trial, run_trials

    again = dataclasses.replace(cfg, camera=dataclasses.replace(cfg.camera, depth=depth))
    if reporter is not None:
        reporter.message(f"trial fit of {asset.name} again, camera.depth {depth}")
    found = None if state is None else state.get("search")
    trial = Trial(
        asset, cfg.trials.iters, mirror, length=float(cand.get("length", 1.0)), motion=motion, found=found
    )
    (res,) = run_trials(video, [trial], again, reporter)
    cand["refit_trial_iou"] = round(res.iou, 4)
    return res.state


# Trial IoU a candidate's semantic score is worth in `trial_score`: chosen on the shared real videos,
# with the leave-one-video-out choice beside it (BENCHMARKS.md, Retrieval: the template zooctl fit
# chooses).
TRIAL_SEMANTIC_WEIGHT = 0.1
# Trial IoU a trial's displacement (`trial_displacement`, a share of the template's size) costs:
# the largest weight that keeps every pick of the seven real videos, below the best one for the
# 28-video benchmark's novel view (BENCHMARKS.md, Fit: the template that changes its shape least).
TRIAL_DISPLACEMENT_WEIGHT = 1.5
TRIAL_NOISE = 0.01  # about what a trial's IoU moves between seeds (BENCHMARKS.md, Fit: template trials)


def trial_score(
    iou: float,
    semantic: float = 0.0,
    displacement: float = 0.0,
    world_spread: float | None = None,
    consistency: float | None = None,
    consistency_weight: float = 0.0,
) -> float:
    """What the template trials rank by: the trial's input-view mask IoU, plus
    `TRIAL_SEMANTIC_WEIGHT` times its candidate's semantic score (0..1: how surely the classifier
    sees that animal or its nearest relative in the bank; 0 without one), less
    `TRIAL_DISPLACEMENT_WEIGHT` times its displacement. An input-view silhouette cannot tell a dog
    from a duck-billed dinosaur seen side on; a classifier sure of a dog can, and a stylised render
    it is not sure of moves the choice by little. A template that had to bulge its surface to
    match the silhouettes is the worse animal from the sides the camera does not see.

    Where the camera turns round the animal (``world_spread``, degrees: `trial_world_spread`),
    less `TRIAL_WORLD_SPREAD_WEIGHT` times how far the trial's body turns in the world: a
    template of the wrong shape matches the outlines of an orbiting camera by turning its body
    frame by frame. There too, plus ``consistency_weight`` (``trials.view_consistency``) times
    the trial's ``consistency`` (`trial_view_consistency`): its body kept as it is at one frame
    and seen from where the camera went, against the masks there."""
    spread = 0.0 if world_spread is None else TRIAL_WORLD_SPREAD_WEIGHT * world_spread
    views = 0.0 if consistency is None else consistency_weight * consistency
    return iou + TRIAL_SEMANTIC_WEIGHT * semantic - TRIAL_DISPLACEMENT_WEIGHT * displacement - spread + views


def close_trials_note(candidates: list[dict[str, Any]], chosen: str, source: str) -> str | None:
    """A note for the user when another tried template's trial IoU is within `TRIAL_NOISE` of the
    chosen one's: the trials could not tell them apart, and the other may be the better animal
    (an input-view IoU says little about the sides the camera does not see)."""
    # a trial stopped at the checkpoint has an IoU of fewer iterations, and was behind there
    tried = {c["name"]: c["trial_iou"] for c in candidates if "trial_iou" in c and "pruned_at" not in c}
    if chosen not in tried:
        return None
    close = [n for n, iou in tried.items() if n != chosen and abs(iou - tried[chosen]) <= TRIAL_NOISE]
    if not close:
        return None
    others = ", ".join(f"{n} ({tried[n]:.3f})" for n in close)
    return (
        f"the template trials could not tell {chosen} (trial IoU {tried[chosen]:.3f}) from {others}: "
        f"within {TRIAL_NOISE}, the trials' own noise. Look at overlay.mp4's side view, and fit "
        f"the other with `zooctl fit {source} --template {close[0]}` if it is the better animal"
    )


def kept_trials(scores: list[float], margin: float) -> list[int]:
    """Indices of the trials whose score (`trial_score`) is within ``margin`` of the best: those
    that go on past the checkpoint (``trials.prune_at``)."""
    return [i for i, x in enumerate(scores) if x >= max(scores) - margin]


def pick_trial(scores: list[float], margin: float = 0.0) -> int:
    """Index of the winning trial by its `trial_score`: the first in retrieval order within
    ``margin`` of the best (``margin`` 0: the best, ties keeping the retrieval order)."""
    top = max(scores)
    return next(i for i, x in enumerate(scores) if x >= top - margin)
