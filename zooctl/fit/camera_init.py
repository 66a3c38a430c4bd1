"""Camera and root initialisation from the masks (CASA supplement I).

The camera sits at the origin looking down world -Z (see `zooctl.fit.scene`), so choosing a
viewpoint on a sphere around the animal is choosing the animal's root rotation. For every
candidate (azimuth, elevation, roll, focal) the template's rest pose is rotated, its scale and
translation set by aligning its projected bounding box with the mask's, its hard silhouette
rendered and scored by IoU against the masks of a few frames. The best candidate is refined on a
finer local grid, then *tracked*: every ``track_every`` frames a small grid around the previous
keyframe's rotation is scored on that keyframe, so camera motion and turning animals are
followed. Frames between keyframes get slerped rotations; every frame's translation comes from
its own bounding-box alignment (frames whose mask is empty interpolate their neighbours').

With known camera rotations (a calibrated or tracked camera, or the benchmark's own cameras:
CASA's protocol on synthetic data) nothing is tracked: the animal's orientation in the world is
one unknown, each frame's root rotation follows from it through the camera's motion, and every
candidate is scored on keyframes spread over the whole video. Silhouettes alone cannot tell an
animal turning one way from its depth mirror turning the other; the camera's known motion can.
An animal that itself turns far in the world (a fish swimming round) gets the one orientation
that fits its keyframes best, and the optimisation has to follow the rest.

With the camera's motion estimated from the background (``camera.motion = "background"``,
`zooctl.video.camera_motion`), the camera's turn is a prediction, not a fact: the tracker's small
grid is centred on the previous keyframe carried by the camera's turn since, so the animal's own
turn is still searched, and each of a few distinct good starts is tracked that way, the track
whose keyframes fit best kept (a start and its mirror cast the same first frames; turned by the
camera over the video, only one of them keeps fitting).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from ..geometry import matrix_to_quat, quat_slerp, quat_to_matrix, rotation_angle_deg
from .config import CameraConfig
from .scene import CAMERA_ROTATION


@dataclass
class CameraInit:
    """focal in fit pixels; root_rotation (T, 4) wxyz; root_translation (T, 3); candidates: the
    best scored candidates of the global search (for fit.json); iou: frame-0 search IoU;
    present: the frames whose mask the search saw (those the distance rule reads,
    `placed_at_depth`)."""

    focal: float
    root_rotation: np.ndarray
    root_translation: np.ndarray
    candidates: list[dict] = field(default_factory=list)
    iou: float = 0.0
    keyframe_iou: list[float] = field(default_factory=list)
    present: list[int] = field(default_factory=list)


def view_rotation(azimuth: float, elevation: float, roll: float = 0.0) -> np.ndarray:
    """(3, 3) root rotation ``Rz(roll) Rx(elevation) Ry(azimuth)`` (degrees)."""
    a, e, r = (math.radians(x) for x in (azimuth, elevation, roll))
    ry = np.array([[math.cos(a), 0, math.sin(a)], [0, 1, 0], [-math.sin(a), 0, math.cos(a)]])
    rx = np.array([[1, 0, 0], [0, math.cos(e), -math.sin(e)], [0, math.sin(e), math.cos(e)]])
    rz = np.array([[math.cos(r), -math.sin(r), 0], [math.sin(r), math.cos(r), 0], [0, 0, 1]])
    return rz @ rx @ ry


def mask_box(mask: np.ndarray) -> np.ndarray | None:
    """(4,) x0, y0, x1, y1 pixel-edge bounds of a boolean mask, or None when empty."""
    ys, xs = np.nonzero(mask)
    if len(xs) == 0:
        return None
    return np.array([xs.min(), ys.min(), xs.max() + 1, ys.max() + 1], np.float64)


# How far (log of the size ratio) a box alignment's projected box may be from its target after the
# fixed-point passes: about 1 % of its size, half a pixel at the search's 64 px.
SETTLED = 0.01


def align_translation(
    points: np.ndarray, box: np.ndarray, focal: float, cx: float, cy: float, iterations: int = 3
) -> np.ndarray:
    """(3,) world translation that puts rotated points (N, 3) so their projected box matches ``box``.

    Depth from the geometric mean of the width and height ratios, centre by back-projection;
    a few fixed-point passes correct for perspective. Where they do not settle (a body long along
    the view and near the camera, whose near end's projection grows faster than the pass assumes),
    the depth is bisected instead.
    """
    cam = points @ CAMERA_ROTATION.T  # camera frame (the camera is at the origin)
    c0 = 0.5 * (cam.max(0) + cam.min(0))
    ext = np.maximum(cam.max(0) - cam.min(0), 1e-9)
    bw, bh = max(box[2] - box[0], 1.0), max(box[3] - box[1], 1.0)
    d = focal * math.sqrt(ext[0] * ext[1] / (bw * bh)) + ext[2] / 2
    shift = np.array([0.0, 0.0, d]) - c0  # object centre on the optical axis at depth d
    target = np.array([(box[0] + box[2]) / 2, (box[1] + box[3]) / 2])
    nearest = float((cam[:, 2] - c0[2]).min())  # the nearest point's depth less the centre's

    def size_ratio(sh: np.ndarray) -> float:
        lo, hi = _projected_box(cam + sh, focal, cx, cy)
        return math.sqrt(max(hi[0] - lo[0], 1e-6) * max(hi[1] - lo[1], 1e-6) / (bw * bh))

    def centred(sh: np.ndarray, near: bool = False) -> np.ndarray:
        """The box's centre moved onto the target's: as the body's centre would move, or (``near``)
        as its nearest point would, which never overshoots (no edge moves faster than it)."""
        lo, hi = _projected_box(cam + sh, focal, cx, cy)
        sh = sh.copy()
        sh[:2] += (target - 0.5 * (lo + hi)) / focal * (sh[2] + c0[2] + (nearest if near else 0.0))
        return sh

    for _ in range(iterations):
        # scaling the centre about the camera keeps its projection
        shift = centred((shift + c0) * size_ratio(shift) - c0)
    if abs(math.log(size_ratio(shift))) <= SETTLED and shift[2] + c0[2] + nearest > 0:
        return CAMERA_ROTATION.T @ shift  # camera-frame shift back to world (R is its own inverse)
    # The projected box shrinks as the body moves away along the ray through the box's centre:
    # bisect that depth (log scale) between the nearest point just in front of the camera and far.
    ray = np.array([(target[0] - cx) / focal, (target[1] - cy) / focal, 1.0])

    def at(log_depth: float) -> np.ndarray:  # the centre at that depth, the box then centred
        sh = ray * math.exp(log_depth) - c0
        for _ in range(20):
            sh, was = centred(sh, near=True), sh
            if np.abs(sh[:2] - was[:2]).max() * focal <= 0.01 * (sh[2] + c0[2] + nearest):
                break  # moved by under a hundredth of a pixel
        return sh

    lo_d, hi_d = math.log(max(-nearest, 0.0) + 1e-3 * float(ext.max())), math.log(max(d, 1.0) * 1e3)
    for _ in range(40):
        mid = 0.5 * (lo_d + hi_d)
        if size_ratio(at(mid)) > 1.0:
            lo_d = mid
        else:
            hi_d = mid
    return CAMERA_ROTATION.T @ at(hi_d)


def _projected_box(p: np.ndarray, focal: float, cx: float, cy: float) -> tuple[np.ndarray, np.ndarray]:
    z = np.maximum(p[:, 2], 1e-6)
    uv = p[:, :2] / z[:, None] * focal + np.array([cx, cy])
    return uv.min(0), uv.max(0)


def hull_points(points: np.ndarray) -> np.ndarray:
    """The vertices of the convex hull of points (N, 3) (all of them when it is flat or tiny).

    A projected bounding box depends on these alone: x / z on a convex polytope in front of the
    camera is extreme at a vertex."""
    from scipy.spatial import ConvexHull, QhullError

    if len(points) < 5:
        return points
    try:
        return points[ConvexHull(points).vertices]
    except QhullError:
        return points


class SilhouetteScorer:
    """Hard-silhouette IoU of rotated, box-aligned templates against masks at a small size."""

    def __init__(
        self,
        rest: np.ndarray,
        faces: np.ndarray,
        masks: np.ndarray,
        size: int,
        principal: tuple[float, float] | None = None,
    ):
        T, H, W = masks.shape
        s = min(1.0, size / max(H, W))
        self.h, self.w = max(8, round(H * s)), max(8, round(W * s))
        import cv2

        self.masks = np.stack(
            [
                cv2.resize(m.astype(np.float32), (self.w, self.h), interpolation=cv2.INTER_AREA) >= 0.5
                for m in masks
            ]
        )
        self.boxes = [mask_box(m) for m in self.masks]
        self.rest = rest - 0.5 * (rest.max(0) + rest.min(0))
        self.hull = hull_points(self.rest)
        self.faces = np.asarray(faces, dtype=np.int64)
        self.scale = self.h / H  # search pixels per input pixel
        cx, cy = principal if principal is not None else (W / 2, H / 2)
        self.cx, self.cy = cx * self.scale, cy * self.scale

    def place(self, rotation: np.ndarray, frame: int, focal: float) -> np.ndarray | None:
        """World translation of the centred rest template rotated by ``rotation`` for ``frame``."""
        box = self.boxes[frame]
        if box is None:
            return None
        return align_translation(self.hull @ rotation.T, box, focal * self.scale, self.cx, self.cy)

    def silhouette(self, verts: np.ndarray, focal: float) -> np.ndarray:
        """(h, w) bool hard silhouette of world vertices (V, 3): every face filled by OpenCV at once."""
        import cv2

        cam = verts @ CAMERA_ROTATION.T
        z = np.maximum(cam[:, 2], 1e-6)
        uv = cam[:, :2] / z[:, None] * (focal * self.scale) + np.array([self.cx, self.cy])
        # Clip: vertices next to the camera plane project far away and would overflow int32.
        uv = np.clip(np.nan_to_num(uv, nan=-1e5), -1e5, 1e5)
        front = self.faces[(cam[self.faces, 2] > 1e-3).all(1)]
        tri = np.round(uv[front] * 16 - 8).astype(np.int32)  # 4 fractional bits; pixel centres at +0.5
        img = np.zeros((self.h, self.w), np.uint8)
        cv2.fillPoly(img, list(tri), 1, lineType=cv2.LINE_8, shift=4)
        return img.astype(bool)

    def score(self, rotations: list[np.ndarray], frames: list[int], focals: list[float]) -> np.ndarray:
        """(N,) mean IoU over ``frames`` for N (rotation, focal) candidates."""
        total = np.zeros(len(rotations))
        for fr in frames:
            m = self.masks[fr]
            for n, (R, f) in enumerate(zip(rotations, focals, strict=True)):
                sil = self.silhouette(self.rest @ R.T + self.place(R, fr, f), f)
                total[n] += (sil & m).sum() / max((sil | m).sum(), 1)
        return total / max(len(frames), 1)


def initialise_camera(
    rest: np.ndarray,
    faces: np.ndarray,
    masks: np.ndarray,
    cfg: CameraConfig,
    fit_scale: float,
    seed: int = 0,
    principal: tuple[float, float] | None = None,
    image_height: int | None = None,
    camera_rotations: np.ndarray | None = None,
    start: np.ndarray | None = None,
    turned: bool = False,
    camera_motion: np.ndarray | None = None,
) -> CameraInit:
    """Search focal and viewpoint, track the root rotation, align every frame (module docstring).

    rest (V, 3) template rest vertices; faces (F, 3); masks (T, H, W) bool at the input size (or a
    crop of the input around the animal, with ``principal`` the principal point in the crop's
    pixels and ``image_height`` the uncropped height that the focal candidates refer to);
    fit_scale: fit pixels per input pixel; camera_rotations: (T, 3, 3) world-to-camera rotations
    of the video's camera (OpenCV axes: x right, y down, z forward) when they are known;
    ``start``: (3, 3) the first frame's root rotation, known (a window of a long clip continuing
    the one before it): no search, only the tracking and the alignment, at ``cfg.focal``.
    ``turned``: start from the best view at least 90 degrees of azimuth from the search's best
    instead (the animal facing the other way). ``camera_motion``: (T, 3, 3) world-to-camera
    rotations estimated from the background (`zooctl.video.camera_motion`), a prediction: the
    search and the tracker score each frame's rotation carried by the camera's turn since the
    search's frame, the animal's own turn still searched (ignored when ``camera_rotations`` are
    known). Returns a `CameraInit` in fit pixels.
    """
    T, H, W = masks.shape
    principal = principal if principal is not None else (W / 2, H / 2)
    scorer = SilhouetteScorer(rest, faces, masks, cfg.search_size, principal)
    present = [t for t in range(T) if scorer.boxes[t] is not None]
    first = present[0]
    head = [t for t in present if t < first + max(cfg.track_every, 1)]
    frames = [head[int(round(i))] for i in np.linspace(0, len(head) - 1, min(cfg.search_frames, len(head)))]
    frames = sorted(set(frames))
    follow = None
    if camera_motion is not None and camera_rotations is None:
        follow = camera_follow(np.asarray(camera_motion, np.float64), first)

    def track(
        rotation: np.ndarray,
        focal: float,
        iou: float,
        top: list,
        turn: float | None = None,
        place: bool = True,
    ) -> CameraInit:
        return _tracked(
            scorer,
            masks,
            cfg,
            rest,
            principal,
            present,
            first,
            rotation,
            focal,
            iou,
            top,
            fit_scale,
            turn,
            follow,
            place,
        )

    if start is not None:
        if cfg.focal is None:
            raise ValueError("a known start rotation needs a known focal")
        focal = float(cfg.focal)
        iou = float(scorer.score([start], [first], [focal])[0])
        return track(start, focal, iou, [])
    if cfg.focal is not None:
        focals = [float(cfg.focal)]
    else:
        focals = [0.5 * (image_height or H) / math.tan(math.radians(fov) / 2) for fov in cfg.fov_candidates]
    cands = []
    for f in focals:
        for el in cfg.elevations:
            for az in np.arange(cfg.azimuths) * 360.0 / cfg.azimuths:
                for roll in cfg.rolls:
                    cands.append((float(az), float(el), float(roll), f))
    if camera_rotations is not None:
        # Keyframes over the whole video; a candidate is the root rotation at ``first``, and the
        # camera's motion carries it to every other frame.
        frames = _spread_keyframes(present, cfg)
        known = camera_follow(np.asarray(camera_rotations, np.float64), first)
        score = lambda rots, fs: _score_followed(scorer, known, rots, frames, fs)  # noqa: E731
    elif follow is not None:
        score = lambda rots, fs: _score_followed(scorer, follow, rots, frames, fs)  # noqa: E731
    else:
        score = lambda rots, fs: scorer.score(rots, frames, fs)  # noqa: E731
    scores = score([view_rotation(*c[:3]) for c in cands], [c[3] for c in cands])
    order = np.argsort(-scores)
    if turned:
        az0 = cands[order[0]][0]
        order = np.asarray([i for i in order if abs((cands[i][0] - az0 + 180.0) % 360.0 - 180.0) >= 90.0])
    best = cands[order[0]]
    top = [
        {
            "azimuth": cands[i][0],
            "elevation": cands[i][1],
            "roll": cands[i][2],
            "focal": cands[i][3] / 1.0,
            "iou": float(scores[i]),
        }
        for i in order[:5]
    ]
    # Local refinement: a finer grid around the best view (and focal, unless given).
    step = 360.0 / cfg.azimuths / 2
    fsteps = [1.0] if cfg.focal is not None else [0.85, 1.0, 1.18]

    def refine(
        c: tuple[float, float, float, float], by: Callable | None = None
    ) -> tuple[tuple[float, float, float, float], float]:
        local = [
            (c[0] + da, c[1] + de, c[2] + dr, c[3] * fs)
            for da in (-step, 0.0, step)
            for de in (-step / 2, 0.0, step / 2)
            for dr in (-step / 2, 0.0, step / 2)
            for fs in fsteps
        ]
        lscores = (by or score)([view_rotation(*x[:3]) for x in local], [x[3] for x in local])
        return local[int(np.argmax(lscores))], float(lscores.max())

    if follow is not None and cfg.track != "steady":
        # The first frames cannot tell a view from its mirror turning the other way; the camera's
        # turn over the whole video can: each distinct good start is tracked, the best track kept.
        starts = [(c, score) for c in _distinct_starts([cands[i] for i in order])]
        if cfg.search_over == "both":
            keys = _spread_keyframes(present, cfg)
            whole = lambda rots, fs: _score_followed(scorer, follow, rots, keys, fs)  # noqa: E731
            ws = whole([view_rotation(*c[:3]) for c in cands], [c[3] for c in cands])
            seen = [view_rotation(*c[:3]) for c, _ in starts]
            for c in _distinct_starts([cands[i] for i in np.argsort(-ws)]):
                R = view_rotation(*c[:3])
                if all(rotation_angle_deg(R @ Q.T) >= cfg.track_step for Q in seen):
                    starts.append((c, whole))
                    seen.append(R)
        tracks = []
        for c, by in starts:
            b, i = refine(c, by)
            if by is not score:  # every track's start scored alike, on the search's frames
                i = float(score([view_rotation(*b[:3])], [b[3]])[0])
            tracks.append(track(view_rotation(*b[:3]), b[3], i, top, place=False))
        kept = max(tracks, key=lambda x: float(np.mean(x.keyframe_iou)))
        focal = kept.focal / fit_scale
        trans = _box_translations(
            scorer, masks, kept.root_rotation, rest, focal, principal, present, cfg.depth
        )
        return replace(kept, root_translation=trans)
    best, iou = refine(best)
    focal = best[3]
    if camera_rotations is not None:
        R0 = view_rotation(*best[:3])
        rot_q = np.stack([matrix_to_quat(known[t] @ R0) for t in range(T)])
        key_iou = [float(scorer.score([known[k] @ R0], [k], [focal])[0]) for k in frames]
        return CameraInit(
            focal * fit_scale,
            rot_q,
            _box_translations(scorer, masks, rot_q, rest, focal, principal, present, cfg.depth),
            top,
            iou,
            key_iou,
            list(present),
        )
    rotation = view_rotation(*best[:3])
    if cfg.track == "steady":
        start, turn = _steady_turn(scorer, cfg, present, first, best[:3], focal, follow)
        return track(start, focal, iou, top, turn)
    return track(rotation, focal, iou, top)


_MOTION_STARTS = 4  # distinct starts tracked when the camera's motion is estimated
_DISTINCT_DEG = 60.0


def _distinct_starts(
    ranked: list[tuple[float, float, float, float]],
) -> list[tuple[float, float, float, float]]:
    """The best `_MOTION_STARTS` of ``ranked`` candidates (azimuth, elevation, roll, focal; best
    first) whose views differ pairwise by at least `_DISTINCT_DEG` degrees of rotation."""
    kept: list[tuple[float, float, float, float]] = []
    rots: list[np.ndarray] = []
    for c in ranked:
        R = view_rotation(*c[:3])
        if all(rotation_angle_deg(R @ Q.T) >= _DISTINCT_DEG for Q in rots):
            kept.append(c)
            rots.append(R)
            if len(kept) == _MOTION_STARTS:
                break
    return kept


def _yaw(degrees: float) -> np.ndarray:
    return view_rotation(degrees, 0.0, 0.0)


def _steady_turn(
    scorer: SilhouetteScorer,
    cfg: CameraConfig,
    present: list[int],
    first: int,
    start: tuple[float, float, float],
    focal: float,
    follow: np.ndarray | None = None,
) -> tuple[np.ndarray, float]:
    """(the start rotation at ``first``, the turn in degrees per frame about the template's up
    axis) whose steady turn best fits keyframes spread over the whole video.

    A camera circling the animal, or an animal turning on the spot, turns the root about the
    animal's own up axis (``R_t = R_0 Ry(w t)``) at a rate that changes slowly. Scored over the
    whole video, the turn is seen where a keyframe-to-keyframe tracker meets a view whose silhouette
    barely changes with the yaw (an elongated body seen end on) and may turn back. ``start``: the
    search's best view (azimuth, elevation, roll); turns over the video of up to one full circle
    either way, in steps of ``track_step``, then a finer grid around the best (the start's azimuth
    too). Alone it loses more fits than it mends (BENCHMARKS.md, "Where the own rig's novel view is
    lost now"): `zooctl.fit.named_start.start_trial` tries it beside the greedy track. ``follow``
    (`camera_follow` of the camera's estimated motion): the turn is the animal's own, the camera's
    carried on top."""
    keys = _spread_keyframes(present, cfg)
    span = max(present[-1] - first, 1)
    step = max(cfg.track_step, 1.0)

    def scored(cands: list[tuple[float, float, float, float]]) -> np.ndarray:
        total = np.zeros(len(cands))
        for k in keys:
            rots = [view_rotation(c[0] + c[3] * (k - first), c[1], c[2]) for c in cands]
            if follow is not None:
                rots = [follow[k] @ R for R in rots]
            total += scorer.score(rots, [k], [focal] * len(rots))
        return total / len(keys)

    turns = np.arange(-360.0, 360.0 + step / 2, step) / span
    coarse = [(*start, float(w)) for w in turns]
    best = coarse[int(np.argmax(scored(coarse)))]
    fine = [
        (best[0] + da, best[1], best[2], best[3] + dw / span)
        for da in (-step / 2, 0.0, step / 2)
        for dw in (-step / 2, -step / 4, 0.0, step / 4, step / 2)
    ]
    best = fine[int(np.argmax(scored(fine)))]
    return view_rotation(*best[:3]), float(best[3])


def _tracked(
    scorer: SilhouetteScorer,
    masks: np.ndarray,
    cfg: CameraConfig,
    rest: np.ndarray,
    principal: tuple[float, float],
    present: list[int],
    first: int,
    rotation: np.ndarray,
    focal: float,
    iou: float,
    top: list[dict[str, float]],
    fit_scale: float,
    turn: float | None = None,
    follow: np.ndarray | None = None,
    place: bool = True,
) -> CameraInit:
    """The root rotation tracked over keyframes from ``rotation`` at frame ``first``, every
    frame aligned to its mask's box (the camera search's last steps). ``turn`` (degrees a frame
    about the template's up axis, `_steady_turn`): each keyframe's small turns are of the steady
    turn's prediction, at half the step, instead of the keyframe before. ``follow`` (T, 3, 3)
    (`camera_follow` of the camera's estimated motion): the prediction is carried by the camera's
    turn since the keyframe before (since ``first`` for the steady turn's). ``place`` False: no
    per-frame box alignment (the translations left zero), for a track that may not be kept."""
    T = len(masks)
    key_rot = {first: rotation}
    key_iou = [iou]
    prev, last = key_rot[first], first
    ts = cfg.track_step if turn is None else cfg.track_step / 2
    deltas = [
        view_rotation(a, e, r) for a in (-ts, 0.0, ts) for e in (-ts, 0.0, ts) for r in (-ts / 2, 0.0, ts / 2)
    ]
    for k in range(first + cfg.track_every, T, max(cfg.track_every, 1)):
        if scorer.boxes[k] is None:
            continue
        if turn is not None:
            prev = rotation @ _yaw(turn * (k - first))
            if follow is not None:
                prev = follow[k] @ prev
        elif follow is not None:
            prev = follow[k] @ follow[last].T @ prev
        rots = [prev @ d for d in deltas] + [d @ prev for d in deltas]
        sc = scorer.score(rots, [k], [focal] * len(rots))
        prev, last = rots[int(np.argmax(sc))], k
        key_rot[k] = prev
        key_iou.append(float(sc.max()))
    # Per-frame rotations by slerp between keyframes (held constant outside them).
    keys = sorted(key_rot)
    kq = np.stack([matrix_to_quat(key_rot[k]) for k in keys])
    rot_q = np.zeros((T, 4))
    for t in range(T):
        j = int(np.searchsorted(keys, t, side="right")) - 1
        if j < 0:
            rot_q[t] = kq[0]
        elif j >= len(keys) - 1:
            rot_q[t] = kq[-1]
        else:
            a = (t - keys[j]) / (keys[j + 1] - keys[j])
            rot_q[t] = quat_slerp(kq[j], kq[j + 1], a)
    trans = (
        _box_translations(scorer, masks, rot_q, rest, focal, principal, present, cfg.depth)
        if place
        else np.zeros((T, 3))
    )
    return CameraInit(focal * fit_scale, rot_q, trans, top, iou, key_iou, list(present))


_MAX_KNOWN_KEYFRAMES = 10


def _spread_keyframes(present: list[int], cfg: CameraConfig) -> list[int]:
    """Every ``track_every``-th frame with a mask, at most `_MAX_KNOWN_KEYFRAMES` spread evenly
    over them: the keyframes a whole-video score sums over."""
    frames = present[:: max(cfg.track_every, 1)]
    if len(frames) > _MAX_KNOWN_KEYFRAMES:
        frames = [frames[int(round(i))] for i in np.linspace(0, len(frames) - 1, _MAX_KNOWN_KEYFRAMES)]
    return frames


def camera_follow(camera_rotations: np.ndarray, first: int) -> np.ndarray:
    """(T, 3, 3) F_t such that F_t @ R is frame t's root rotation when R is frame ``first``'s and
    the animal keeps its orientation in the world while the camera moves (camera_rotations
    (T, 3, 3) world-to-camera, OpenCV axes; the fit's camera is fixed at `CAMERA_ROTATION`)."""
    C = camera_rotations
    return CAMERA_ROTATION.T @ C @ C[first].T @ CAMERA_ROTATION


def _score_followed(
    scorer: SilhouetteScorer,
    follow: np.ndarray,
    rots: list[np.ndarray],
    frames: list[int],
    focals: list[float],
) -> np.ndarray:
    total = np.zeros(len(rots))
    for k in frames:
        total += scorer.score([follow[k] @ R for R in rots], [k], focals)
    return total / max(len(frames), 1)


def _box_translations(
    scorer: SilhouetteScorer,
    masks: np.ndarray,
    rot_q: np.ndarray,
    rest: np.ndarray,
    focal: float,
    principal: tuple[float, float],
    present: list[int],
    depth: str,
) -> np.ndarray:
    """(T, 3) each frame's own box alignment at the input resolution's camera (frames whose mask
    is empty interpolate their neighbours'), its distances then as ``depth`` says
    (`CameraConfig.depth`, `_depth_held`)."""
    T, H, W = masks.shape
    trans = np.full((T, 3), np.nan)
    full = SilhouetteScorer.__new__(SilhouetteScorer)
    full.rest, full.hull, full.boxes = scorer.rest, scorer.hull, [mask_box(m) for m in masks]
    full.scale, full.w, full.h = 1.0, W, H
    full.cx, full.cy = principal
    centre = 0.5 * (rest.max(0) + rest.min(0))
    for t in present:
        R = quat_to_matrix(rot_q[t])
        # The scorer centres the template; the model rotates it about its own origin.
        trans[t] = full.place(R, t, focal) - R @ centre
    idx = np.array(present)
    for c in range(3):
        trans[:, c] = np.interp(np.arange(T), idx, trans[idx, c])
    return trans if depth == "box" else _depth_held(trans, rot_q, centre, idx, depth)


def placed_at_depth(init: CameraInit, rest: np.ndarray, found: str, depth: str) -> CameraInit | None:
    """``init``, a search's start whose distances ``found`` (`CameraConfig.depth`) placed, with
    its distances as ``depth`` says instead; None where ``found``'s cannot give them (only each
    frame's own box distance gives the others). The search's rotations and focal do not depend
    on the rule, its last step alone does (`_box_translations`): a template trial's search at one
    rule serves a fit at another. rest (V, 3): the template's rest vertices, as searched."""
    if found == depth:
        return init
    if found != "box" or len(init.present) == 0:
        return None
    centre = 0.5 * (rest.max(0) + rest.min(0))
    trans = _depth_held(
        np.asarray(init.root_translation, np.float64),
        np.asarray(init.root_rotation, np.float64),
        centre,
        np.array(init.present),
        depth,
    )
    return replace(init, root_translation=trans)


def _depth_held(
    trans: np.ndarray, rot_q: np.ndarray, centre: np.ndarray, present: np.ndarray, depth: str
) -> np.ndarray:
    """(T, 3) ``trans`` with each frame's body centre moved along its ray (its projection kept) to
    the distance of ``depth`` (`CameraConfig.depth`): ``trend`` the least-squares line of the log
    distances of the ``present`` frames over time, ``held`` their median."""
    T = len(trans)
    if len(present) < 2:
        return trans
    R = quat_to_matrix(np.asarray(rot_q, np.float64))  # (T, 3, 3)
    body = trans + R @ centre  # (T, 3); the camera looks down -Z
    log_d = np.log(np.maximum(-body[:, 2], 1e-9))
    if depth == "held":
        want = np.full(T, np.median(log_d[present]))
    else:
        slope, at0 = np.polyfit(present.astype(np.float64), log_d[present], 1)
        want = slope * np.arange(T) + at0
    return body * np.exp(want - log_d)[:, None] - R @ centre
