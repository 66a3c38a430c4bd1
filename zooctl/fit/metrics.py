"""CASA's evaluation metrics (section 4), for fits of videos with ground truth (`zooctl bench make`).

Both shapes are compared in their own camera's frame (the fit's camera, the benchmark's camera of
that frame), so the image alignment is common. A monocular fit is only known up to a scale along
the camera rays, so the prediction is scaled about the camera centre by the factor that maximises
the voxel IoU (CASA's line search), per evaluated frame; every 3D metric of a frame uses its scale.
Lengths are divided by the longest side of the ground truth's bounding box.

- ``miou``: IoU of 32^3 voxelisations (surface samples, interiors filled), after the line search;
- ``mcham``: symmetric Chamfer distance (mean L2, both directions averaged) of surface samples;
- ``joint``: CD-J2J, the same Chamfer distance between joint positions (skinning joints only);
- ``skinning``: per-joint vertex sets (argmax weight; prediction transferred to the ground-truth
  vertices by nearest neighbour) matched by Jonker-Volgenant (`linear_sum_assignment`) on
  1 - IoU; the mean IoU of the matched sets (unmatched ground-truth joints count 0);
- ``reanimation``: joint rotations (and root) of the fitted model, from its last frame, optimised
  by Chamfer distance to match the held-out novel ground-truth pose (``gt_novel_vertices``, seen by
  the last frame's camera); the final ``mcham`` to it, at the last frame's line-search scale;
- ``tilt_error``: the mean over the evaluated frames of how far the fit's longest axis leaves the
  image plane (`axis_tilt`, degrees) less the truth's: negative when the fit lies flatter across
  the view than the animal, which the input silhouettes barely show (``axis_tilt``: both per frame);
  it reads the turn only where the template has the animal's body plan (a biped's longest axis is
  its height, a dog's its length);
- ``novel_view_iou``: 2D mask IoU seen from the cameras the fit never sees (``gt_view_*`` of
  `zooctl.benchdata.make`: +90 degrees azimuth, +35 degrees elevation), on the same evaluated
  frames: the fit in its camera's frame, scaled about the camera centre by that frame's mIoU
  line-search factor, is placed in the benchmark's input camera of the frame (the alignment every
  3D metric uses), then projected through each held-out camera with the benchmark's intrinsics;
  ``novel_view_iou_per_view`` the mean per camera. None for videos made without those views;
- ``mask_iou``: 2D IoU of the fitted silhouettes with the masks (computed by the fit itself).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from ..errors import InputError
from ..geometry import silhouette_iou

GRID = 32


def surface_samples(vertices: np.ndarray, faces: np.ndarray, n: int = 3000, seed: int = 0) -> np.ndarray:
    """(n, 3) area-weighted random points on a triangle mesh (V, 3), (F, 3)."""
    rng = np.random.default_rng(seed)
    tri = vertices[faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    p = area / area.sum() if area.sum() > 0 else None
    f = rng.choice(len(faces), n, p=p)
    r1, r2 = np.sqrt(rng.random(n)), rng.random(n)
    w = np.stack((1 - r1, r1 * (1 - r2), r1 * r2), 1)
    return (tri[f] * w[..., None]).sum(1)


def voxelize(points: np.ndarray, lo: np.ndarray, size: float, grid: int = GRID) -> np.ndarray:
    """(grid,)*3 bool occupancy of surface points, interiors filled (cube [lo, lo + size])."""
    from scipy import ndimage

    idx = np.floor((points - lo) / size * grid).astype(int)
    ok = ((idx >= 0) & (idx < grid)).all(1)
    vox = np.zeros((grid,) * 3, bool)
    vox[tuple(idx[ok].T)] = True
    # Thicken the shell so sampling gaps cannot connect inside and outside, fill, thin it back.
    thick = ndimage.binary_dilation(vox, iterations=1)
    return ndimage.binary_erosion(ndimage.binary_fill_holes(thick), iterations=1, border_value=0) | vox


def chamfer(a: np.ndarray, b: np.ndarray) -> float:
    """Symmetric Chamfer distance (mean L2 distance, the two directions averaged)."""
    from scipy.spatial import cKDTree

    if len(a) == 0 or len(b) == 0:
        return float("nan")
    return 0.5 * float(cKDTree(b).query(a)[0].mean() + cKDTree(a).query(b)[0].mean())


def scale_line_search(
    pred: np.ndarray, gt: np.ndarray, scales: np.ndarray | None = None
) -> tuple[float, float]:
    """(best scale, its voxel IoU): pred surface points (N, 3) scaled about the camera centre (the
    origin of the camera frame) against gt points (M, 3)."""
    lo, hi = gt.min(0), gt.max(0)
    size = float((hi - lo).max()) * 1.5
    lo = 0.5 * (lo + hi) - size / 2
    gvox = voxelize(gt, lo, size)
    base = float(np.median(gt[:, 2]) / max(np.median(pred[:, 2]), 1e-9))  # match the mean depths
    grids = [scales] if scales is not None else [base * np.exp(np.linspace(-0.4, 0.4, 9))]
    best = (1.0, -1.0)
    for level in range(2 if scales is None else 1):
        if level == 1:  # fine: around the coarse optimum
            grids.append(best[0] * np.exp(np.linspace(-0.1, 0.1, 9)))
        for s in grids[level]:
            pv = voxelize(pred * s, lo, size)
            iou = (pv & gvox).sum() / max((pv | gvox).sum(), 1)
            if iou > best[1]:
                best = (float(s), float(iou))
    return best


def skinning_iou(
    gt_verts: np.ndarray, gt_dense: np.ndarray, pred_verts: np.ndarray, pred_dense: np.ndarray
) -> float:
    """Matched per-joint vertex-set IoU (module docstring). Vertices in a common frame."""
    from scipy.optimize import linear_sum_assignment
    from scipy.spatial import cKDTree

    nn = cKDTree(pred_verts).query(gt_verts)[1]
    g = gt_dense.argmax(1)
    p = pred_dense[nn].argmax(1)
    gj = np.unique(g)
    pj = np.unique(p)
    G = np.stack([g == j for j in gj])  # (Jg, V)
    P = np.stack([p == j for j in pj])  # (Jp, V)
    inter = G.astype(np.float64) @ P.T.astype(np.float64)
    union = G.sum(1)[:, None] + P.sum(1)[None] - inter
    iou = inter / np.maximum(union, 1)
    r, c = linear_sum_assignment(1.0 - iou)
    return float(iou[r, c].sum() / len(gj))


def _camera_frame_gt(result, t: int) -> tuple[np.ndarray, np.ndarray]:
    gt = result.video.gt
    R, tr = gt["cam_rotation"][t], gt["cam_translation"][t]
    return gt["vertices"][t] @ R.T + tr, gt["joints"][t] @ R.T + tr


@torch.no_grad()
def _camera_frame_pred(result, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    scene = result.scene
    pose = scene.pose(torch.as_tensor(frames, device=scene.rotations.device))
    cam = scene.camera(1)
    R = cam.rotation[0].cpu().numpy().astype(np.float64)
    return pose.vertices.cpu().numpy() @ R.T, pose.joints.cpu().numpy() @ R.T


def evaluate_fit(
    result,
    frames: int = 4,
    reanimate_iters: int = 40,
    within: int | None = None,
    views: list[tuple[str, np.ndarray, np.ndarray]] | None = None,
) -> dict[str, Any]:
    """The 3D metrics of a `zooctl.fit.run.FitResult` whose video has ground truth, on ``frames``
    frames spread over the video (over its first ``within`` frames when given: to compare a fit
    of a long clip with a fit of its start). ``views``, when given, receives what the novel-view
    IoU compared, for a picture (`zooctl.fit.outputs.write_novel_view_png`): (camera name, the fit's
    silhouettes (S, H, W), the truth's (S, H, W)) for the input camera and each held-out one."""
    gt = result.video.gt
    need = ("vertices", "faces", "joints", "skin_joints", "skin_weights", "cam_rotation", "cam_translation")
    if any(k not in gt for k in need):
        raise InputError("the video has no complete ground truth")
    T = result.scene.num_frames if within is None else min(within, result.scene.num_frames)
    sel = np.unique(np.linspace(0, T - 1, min(frames, T)).astype(int))
    pv_all, pj_all = _camera_frame_pred(result, sel)
    faces_p = result.template.faces
    faces_g = gt["faces"]
    Vg = gt["vertices"].shape[1]
    Jg = gt["joints"].shape[1]
    gdense = np.zeros((Vg, Jg))
    np.add.at(gdense, (np.arange(Vg)[:, None], gt["skin_joints"]), gt["skin_weights"])
    pdense = result.scene.model.skin.dense(result.scene.num_joints).detach().cpu().numpy()
    g_skinning = gdense.sum(0) > 0
    p_skinning = pdense.sum(0) > 0
    out = {"miou": [], "mcham": [], "joint": [], "skinning": [], "scale": [], "tilt": [], "tilt_truth": []}
    for i, t in enumerate(sel):
        gv, gj = _camera_frame_gt(result, int(t))
        norm = float((gv.max(0) - gv.min(0)).max())
        gs = surface_samples(gv, faces_g)
        ps = surface_samples(pv_all[i], faces_p)
        s, iou = scale_line_search(ps, gs)
        out["scale"].append(s)
        out["miou"].append(iou)
        out["mcham"].append(chamfer(ps * s, gs) / norm)
        out["joint"].append(chamfer(pj_all[i][p_skinning] * s, gj[g_skinning]) / norm)
        out["skinning"].append(skinning_iou(gv, gdense, pv_all[i] * s, pdense))
        out["tilt"].append(axis_tilt(ps))
        out["tilt_truth"].append(axis_tilt(gs))
    res = {k: float(np.mean(v)) for k, v in out.items() if k not in ("scale", "tilt", "tilt_truth")}
    res["axis_tilt"] = {
        k: [round(x, 1) for x in out[n]] for k, n in (("fit", "tilt"), ("truth", "tilt_truth"))
    }
    res["tilt_error"] = float(np.mean(np.subtract(out["tilt"], out["tilt_truth"])))
    seen = held_out_silhouettes(result, sel, pv_all, np.asarray(out["scale"]), input_view=views is not None)
    per_view = None if seen is None else _view_ious(seen[1:] if views is not None else seen)
    if views is not None and seen is not None:
        views.extend(seen)
    res["novel_view_iou"] = None if per_view is None else _finite_mean(per_view)
    res["novel_view_iou_per_view"] = per_view
    # The last frame's own scale (``sel`` always ends with it): re-animation starts from that
    # frame, and a fit whose depth drifts over the video needs another scale on other frames.
    res["reanimation"] = reanimation(result, float(out["scale"][-1]), reanimate_iters)
    res["frames_evaluated"] = [int(t) for t in sel]
    return res


def axis_tilt(points: np.ndarray) -> float:
    """Degrees (0..90) out of the image plane of the longest axis (first principal component) of
    points (N, 3) in a camera's frame (z along the view): 0 when the body lies across the view, 90
    when it points at the camera."""
    c = points - points.mean(0)
    axis = np.linalg.eigh(c.T @ c)[1][:, -1]
    return float(np.degrees(np.arcsin(min(abs(float(axis[2])), 1.0))))


def _finite_mean(v: list[float]) -> float | None:
    a = np.asarray(v, np.float64)
    return float(np.nanmean(a)) if np.isfinite(a).any() else None


@torch.no_grad()
def held_out_silhouettes(
    result, sel: np.ndarray, pred_cam: np.ndarray, scales: np.ndarray, input_view: bool = False
) -> list[tuple[str, np.ndarray, np.ndarray]] | None:
    """(camera name, the fit's silhouettes (S, H, W) bool, the truth's masks (S, H, W) bool) per
    held-out camera (named by its angle from the input camera), on frames ``sel``, as the
    novel-view IoU compares them (module docstring); None without held-out views. ``input_view``:
    first the input camera's, the fit placed the same way against the truth's mesh rendered by
    it. pred_cam (S, V, 3): the fit's vertices in its camera frame; scales (S,)."""
    gt = result.video.gt
    # the held-out cameras' intrinsics: the video's own, or its truth's when the fit read another
    # source (`zooctl.fit.job.attach_truth`) and estimated its focal
    K = result.video.intrinsics if result.video.intrinsics is not None else gt.get("intrinsics")
    if any(k not in gt for k in ("view_masks", "view_rotation", "view_translation")) or K is None:
        return None
    masks = gt["view_masks"][:, sel]  # (C, S, H, W)
    C, S, H, W = masks.shape
    R, t = gt["cam_rotation"][sel], gt["cam_translation"][sel]  # input cameras (S, 3, 3), (S, 3)
    world = np.einsum("svb,sba->sva", pred_cam * scales[:, None, None] - t[:, None], R)  # R^T (p - t)
    faces = np.asarray(result.template.faces)

    def seen_by(rot: np.ndarray, tr: np.ndarray, verts: np.ndarray, tris: np.ndarray) -> np.ndarray:
        return world_silhouettes(verts, tris, K, rot, tr, H, W)

    out: list[tuple[str, np.ndarray, np.ndarray]] = []
    if input_view:
        truth = np.asarray(gt["vertices"][sel])
        out.append(("input", seen_by(R, t, world, faces), seen_by(R, t, truth, np.asarray(gt["faces"]))))
    for c in range(C):
        turn = gt["view_rotation"][c, sel[0]] @ np.asarray(R[0]).T  # from the input camera
        deg = np.degrees(np.arccos(np.clip((np.trace(turn) - 1) / 2, -1.0, 1.0)))
        name = f"held-out {c + 1} ({deg:.0f} deg off)"
        out.append(
            (
                name,
                seen_by(gt["view_rotation"][c, sel], gt["view_translation"][c, sel], world, faces),
                masks[c],
            )
        )
    return out


def world_silhouettes(
    verts: Any, faces: Any, intrinsics: Any, rot: Any, trans: Any, height: int, width: int
) -> np.ndarray:
    """(S, H, W) bool hard silhouettes of world vertices (S, V, 3) with faces (F, 3), seen by S
    cameras: world-to-camera rotations (S, 3, 3), translations (S, 3), one intrinsics (4,)
    (fx, fy, cx, cy) for all."""
    from ..render.camera import Camera
    from ..render.raster import rasterize

    S = len(rot)
    cam = Camera(
        torch.as_tensor(np.tile(np.asarray(intrinsics, np.float64), (S, 1)), dtype=torch.float32),
        torch.as_tensor(rot, dtype=torch.float32),
        torch.as_tensor(trans, dtype=torch.float32),
        height,
        width,
    )
    v = torch.as_tensor(verts, dtype=torch.float32)
    return rasterize(v, torch.as_tensor(faces, dtype=torch.long), cam).mask.numpy()


def novel_view_iou(
    result, sel: np.ndarray, pred_cam: np.ndarray, scales: np.ndarray
) -> list[float | None] | None:
    """Per held-out camera, the mean mask IoU over frames ``sel`` (module docstring); None without
    held-out views. pred_cam (len(sel), V, 3): the fit's vertices in its camera frame; scales (len(sel),)."""
    seen = held_out_silhouettes(result, sel, pred_cam, scales)
    return None if seen is None else _view_ious(seen)


def _view_ious(seen: list[tuple[str, np.ndarray, np.ndarray]]) -> list[float | None]:
    """Per camera of `held_out_silhouettes`, the mean IoU over its frames."""
    return [_finite_mean(silhouette_iou(f, g)) for _, f, g in seen]


def reanimation(result, scale: float, iters: int = 60) -> float:
    """Normalised Chamfer distance after posing the fitted model to the novel ground-truth pose."""
    gt = result.video.gt
    scene = result.scene
    t = scene.num_frames - 1
    if "novel_vertices" not in gt:
        return float("nan")
    R_gt, t_gt = gt["cam_rotation"][t], gt["cam_translation"][t]
    gv = gt["novel_vertices"] @ R_gt.T + t_gt
    target = torch.as_tensor(surface_samples(gv, gt["faces"], 1500), dtype=torch.float32)
    norm = float((gv.max(0) - gv.min(0)).max())
    dev = scene.rotations.device
    rot = scene.rotations[t : t + 1].detach().clone().requires_grad_(True)
    rr = scene.root_rotation[t : t + 1].detach().clone().requires_grad_(True)
    rt = scene.root_translation[t : t + 1].detach().clone().requires_grad_(True)
    opt = torch.optim.Adam([rot, rr, rt], lr=2e-2)
    R = scene.camera(1).rotation[0].detach()
    sub = torch.arange(0, scene.model.num_vertices, max(1, scene.model.num_vertices // 1500), device=dev)
    for _ in range(iters):
        opt.zero_grad()
        v = scene.model(rot, rr, rt).vertices[0][sub] @ R.T * scale
        d = torch.cdist(v, target.to(dev))
        loss = d.min(1).values.mean() + d.min(0).values.mean()
        loss.backward()
        opt.step()
    with torch.no_grad():
        v = (scene.model(rot, rr, rt).vertices[0] @ R.T * scale).cpu().numpy()
    return chamfer(surface_samples(v, result.template.faces), target.numpy().astype(np.float64)) / norm
