"""What the viewer shows of one fit, read from the store: its record, GLB, input frames, masks, the
reprojected silhouette of the fitted character, and the input-view camera.

Everything is read, nothing in the store is written. The camera comes from the fit's USD
(``/World/Camera``) when it is there, else from the record's ``camera`` (focal length, image size
and the fit's convention: a static camera at the origin looking down -Z, +Y up).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from zooctl.errors import NotFoundError, UsageError


@dataclass
class FitView:
    name: str
    record: dict[str, Any]
    glb: bytes
    frames: np.ndarray  # (T, H, W, 3) uint8, the stored video's frames the fit used
    masks: np.ndarray  # (T, H, W) bool, the masks it fitted
    silhouettes: np.ndarray  # (T, H, W) bool, the exported character projected through the camera
    camera: dict[str, Any]  # intrinsics, camera_to_world (OpenGL-style, as three.js), source
    fps: float


def load_fit_view(store: Path, name: str, progress: Any = None) -> FitView:
    """The fit ``name`` of the store at ``store``, ready to show. ``progress(done, total)`` is
    called while the silhouettes are rendered."""
    from zooctl.store.fits import FitStore

    fits = FitStore(store)
    record = fits.get(name)
    if record.get("status") != "done":
        raise UsageError(
            f"fit {name!r} is {record.get('status', 'unfinished')}: there is no fitted character to show",
            hint=f"finish it with `zooctl fit --resume --name {name}`",
        )
    asset = fits.character(name)
    frames, masks = _video(store, record)
    T = min(int(record["frames"]), len(frames))
    frames, masks = frames[:T], masks[:T].astype(bool)
    H, W = frames.shape[1:3]
    camera = input_camera(record, H, W)
    silhouettes = _silhouettes(asset, camera["torch"], T, progress)
    camera.pop("torch")
    return FitView(
        name=name,
        record=record,
        glb=_glb(record, asset),
        frames=frames,
        masks=masks,
        silhouettes=silhouettes,
        camera=camera,
        fps=float(record.get("fps") or 30.0),
    )


def _video(store: Path, record: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """(frames, masks) of the video the fit read: the stored video, or the benchmark folder."""
    stored = record.get("stored_video")
    if stored:
        from zooctl.store.videos import VideoStore

        vs = VideoStore.open(store)
        if not vs.exists(stored):
            raise NotFoundError(
                f"the video {stored!r} this fit was made from is no longer in the store",
                hint="add it again with `zooctl video add`, or view another fit",
            )
        rec = vs.get(stored, what=("frames", "masks"))
        return rec.frames, rec.masks
    from zooctl.fit.inputs import load_fit_video

    source = Path(record["source"])
    if not source.exists():
        raise NotFoundError(
            f"the video {source} this fit was read from is gone", hint="view a fit whose video still exists"
        )
    video = load_fit_video(source, record.get("masks"), int(record["frames"]))
    return video.frames, video.masks


def input_camera(record: dict[str, Any], H: int, W: int) -> dict[str, Any]:
    """The input-view camera as intrinsics at (H, W) plus its camera-to-world matrix."""
    import torch

    from zooctl.render.camera import Camera, from_usd

    usd = record.get("outputs", {}).get("usd")
    cam = _usd_camera(Path(usd), H, W) if usd and Path(usd).is_file() else None
    source = f"{Path(usd).name} /World/Camera" if cam is not None else "fit record (camera.focal_px)"
    if cam is None:
        focal = record.get("camera", {}).get("focal_px")
        if not focal:
            raise NotFoundError("the fit record has no camera", hint="fit the video again")
        # The fit's convention: at the origin looking down -Z with +Y up (OpenCV frame: Y, Z flipped).
        cam = from_usd(1.0, 1.0, float(H) / W, np.eye(4), H, W)
        cam = Camera(
            torch.tensor([[focal, focal, W / 2.0, H / 2.0]], dtype=torch.float32),
            cam.rotation,
            cam.translation,
            H,
            W,
        )
    fx, fy, cx, cy = (float(x) for x in cam.intrinsics[0])
    R = cam.rotation[0].double().numpy()
    t = cam.translation[0].double().numpy()
    c2w = np.eye(4)
    c2w[:3, :3] = R.T @ np.diag([1.0, -1.0, -1.0])
    c2w[:3, 3] = -R.T @ t
    return {
        "fx": fx,
        "fy": fy,
        "cx": cx,
        "cy": cy,
        "width": W,
        "height": H,
        "camera_to_world": c2w.tolist(),
        "source": source,
        "torch": cam,
    }


def _usd_camera(path: Path, H: int, W: int):
    from pxr import Usd, UsdGeom

    from zooctl.render.camera import from_usd

    stage = Usd.Stage.Open(str(path))
    prim = stage.GetPrimAtPath("/World/Camera") if stage else None
    if prim is None or not prim.IsValid():
        return None
    cam = UsdGeom.Camera(prim)
    c2w = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default())).T
    return from_usd(
        cam.GetFocalLengthAttr().Get(),
        cam.GetHorizontalApertureAttr().Get(),
        cam.GetVerticalApertureAttr().Get(),
        c2w,
        H,
        W,
        cam.GetHorizontalApertureOffsetAttr().Get() or 0.0,
        cam.GetVerticalApertureOffsetAttr().Get() or 0.0,
    )


def _silhouettes(asset: Any, camera: Any, T: int, progress: Any = None, batch: int = 8) -> np.ndarray:
    """(T, H, W) bool: the character's ``fit`` clip rasterised through ``camera``."""
    import torch

    from zooctl.render.raster import rasterize

    faces = torch.as_tensor(asset.faces, dtype=torch.long)
    out = []
    with torch.no_grad():
        for s in range(0, T, batch):
            idx = np.arange(s, min(s + batch, T))
            v = torch.as_tensor(asset.pose("fit", idx).astype(np.float32))
            out.append(rasterize(v, faces, camera.expand(len(idx))).mask.numpy().astype(bool))
            if progress is not None:
                progress(int(idx[-1]) + 1, T)
    return np.concatenate(out)


def _glb(record: dict[str, Any], asset: Any) -> bytes:
    """The fit's own GLB; one exported from its stored character when the fit wrote none."""
    glb = record.get("outputs", {}).get("glb")
    if glb and Path(glb).is_file():
        return Path(glb).read_bytes()
    from zooctl.io.gltf_export import glb_bytes, gltf_document

    return glb_bytes(*gltf_document(asset, ["fit"]))
