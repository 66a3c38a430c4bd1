"""Pinhole cameras: the one convention every zooctl renderer and fitter uses.

Camera convention
-----------------
A camera is pinhole intrinsics ``(fx, fy, cx, cy)`` in pixels plus world-to-camera extrinsics
``(R, t)``: a world point X (zooctl world: Y up, right-handed, model units) has camera coordinates
``x_c = R @ X + t`` in the *OpenCV* camera frame: +X right, +Y down, +Z forward (the camera looks
down +Z; points in front have z > 0). Its image position is

    u = fx * x_c / z_c + cx,    v = fy * y_c / z_c + cy

in continuous pixel coordinates whose origin is the *top-left corner* of the image: pixel
(row i, column j) covers [j, j+1) x [i, i+1) and its centre is (j + 0.5, i + 0.5). A centred
principal point is therefore ``(W / 2, H / 2)``; OpenCV's ``K`` (pixel centres at integers)
converts by ``cx = cx_cv + 0.5``, ``cy = cy_cv + 0.5``. Renderers output (B, H, W) images, row 0 at
the top. Faces with a vertex closer than ``near`` to the camera plane are not rendered.

Conversion to and from USD (`to_usd`, `from_usd`). A ``UsdGeom.Camera`` is OpenGL-style: it looks
down its local -Z axis with +Y up, so its local frame is ours with Y and Z negated,
``F = diag(1, -1, -1)``. Its prim transform (camera-to-world) is

    camera_to_world = [[R^T F, -R^T t], [0, 0, 0, 1]]     (column vectors, as in zooctl)

and in USD's row-vector ``Gf.Matrix4d`` it is the transpose of that matrix. Lens and filmback
attributes are in tenths of a scene unit (millimetres on a centimetre stage); only their ratios
matter for the projection. With ``horizontalAperture = A_h`` (we write USD's default 20.955):

    focalLength = fx * A_h / W,              verticalAperture = focalLength * H / fy
    horizontalApertureOffset = (W / 2 - cx) * A_h / W
    verticalApertureOffset   = (cy - H / 2) * A_v / H

(an offset moves the film window, so the image content, and the principal point with it, moves
the other way; USD's +Y is up while image rows go down) and back: ``fx = f W / A_h``,
``fy = f H / A_v``, ``cx = W / 2 - o_h W / A_h``, ``cy = H / 2 + o_v H / A_v``. The image size is not stored on a USD camera; pass it to
`from_usd` (its aspect ratio should be ``A_h / A_v`` for square pixels).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from ..errors import InputError
from . import _kernels

Tensor = torch.Tensor
_FLIP = np.diag([1.0, -1.0, -1.0])
USD_DEFAULT_HORIZONTAL_APERTURE = 20.955


@dataclass
class Camera:
    """A batch of B pinhole cameras sharing one image size (see the module docstring).

    intrinsics (B, 4) = fx, fy, cx, cy in pixels; rotation (B, 3, 3) and translation (B, 3)
    map world to camera; height, width in pixels; near: the nearest renderable depth.
    `project` and `to_camera` of CPU float tensors run as C++ kernels (`zooctl.render._kernels`,
    the same arithmetic, a few times faster with their gradients); elsewhere PyTorch's.
    """

    intrinsics: Tensor
    rotation: Tensor
    translation: Tensor
    height: int
    width: int
    near: float = 1e-3

    def __post_init__(self) -> None:
        B = self.intrinsics.shape[0]
        if (
            self.intrinsics.shape != (B, 4)
            or self.rotation.shape != (B, 3, 3)
            or self.translation.shape != (B, 3)
        ):
            raise InputError(
                "camera tensors must be intrinsics (B, 4), rotation (B, 3, 3), translation (B, 3); got "
                f"{tuple(self.intrinsics.shape)}, {tuple(self.rotation.shape)}, {tuple(self.translation.shape)}"
            )
        if self.height <= 0 or self.width <= 0:
            raise InputError(f"image size must be positive, got {self.height}x{self.width}")

    @property
    def batch_size(self) -> int:
        return int(self.intrinsics.shape[0])

    def to(self, device: torch.device | str | None = None, dtype: torch.dtype | None = None) -> Camera:
        return Camera(
            self.intrinsics.to(device=device, dtype=dtype),
            self.rotation.to(device=device, dtype=dtype),
            self.translation.to(device=device, dtype=dtype),
            self.height,
            self.width,
            self.near,
        )

    def expand(self, batch: int) -> Camera:
        """The same camera(s) for a batch of ``batch`` renders (B must be 1 or ``batch``)."""
        if self.batch_size == batch:
            return self
        if self.batch_size != 1:
            raise InputError(f"a batch of {self.batch_size} cameras cannot render a batch of {batch}")
        return Camera(
            self.intrinsics.expand(batch, 4),
            self.rotation.expand(batch, 3, 3),
            self.translation.expand(batch, 3),
            self.height,
            self.width,
            self.near,
        )

    def to_camera(self, points: Tensor) -> Tensor:
        """World points (B, N, 3) -> camera-frame points (B, N, 3)."""
        tensors = self._kernel_tensors(points, "to_camera_forward")
        if tensors is not None:
            return _ToCameraKernel.apply(*tensors[:3])
        return points @ self.rotation.transpose(-1, -2) + self.translation[:, None, :]

    def project(self, points: Tensor) -> tuple[Tensor, Tensor]:
        """World points (B, N, 3) -> pixel positions (B, N, 2) and depths z_c (B, N)."""
        tensors = self._kernel_tensors(points, "project_forward")
        if tensors is not None:
            return _ProjectKernel.apply(*tensors)
        pc = self.to_camera(points)
        z = pc[..., 2]
        zs = torch.where(z.abs() < 1e-12, torch.full_like(z, 1e-12), z)
        k = self.intrinsics[:, None, :]
        xy = pc[..., :2] / zs[..., None] * k[..., :2] + k[..., 2:]
        return xy, z

    def _kernel_tensors(self, points: Tensor, name: str) -> tuple[Tensor, Tensor, Tensor, Tensor] | None:
        """(points, rotation, translation, intrinsics) for the CPU kernel ``name`` (one camera per
        image of points (B, N, 3)), or None where the PyTorch expressions apply."""
        if points.dim() != 3 or points.shape[-1] != 3 or self.batch_size not in (1, points.shape[0]):
            return None
        if _kernels.kernel_for(name, points, self.rotation, self.translation, self.intrinsics) is None:
            return None
        cam = self.expand(points.shape[0])
        return points, cam.rotation, cam.translation, cam.intrinsics

    def centers(self) -> tuple[Tensor, Tensor]:
        """Optical centres (B, 3) in world coordinates, and viewing directions (B, 3)."""
        c = -(self.rotation.transpose(-1, -2) @ self.translation[..., None]).squeeze(-1)
        return c, self.rotation[:, 2, :]


def look_at(
    eye: Any,
    target: Any,
    height: int,
    width: int,
    fov_y_degrees: float = 40.0,
    up: Any = (0.0, 1.0, 0.0),
    dtype: torch.dtype = torch.float32,
    device: torch.device | str | None = None,
) -> Camera:
    """Cameras at ``eye`` (B, 3) or (3,) looking at ``target``, world ``up`` up in the image.

    Square pixels, centred principal point, vertical field of view ``fov_y_degrees``.
    """
    eye = np.atleast_2d(np.asarray(eye, dtype=np.float64))
    target = np.broadcast_to(np.asarray(target, dtype=np.float64), eye.shape)
    up = np.asarray(up, dtype=np.float64)
    z = target - eye
    z /= np.linalg.norm(z, axis=-1, keepdims=True)
    x = np.cross(z, up)  # right-handed: x = forward x up; then y = z x x points image-down
    n = np.linalg.norm(x, axis=-1, keepdims=True)
    if np.any(n < 1e-9):
        raise InputError("look_at: the viewing direction is parallel to 'up'", hint="pass another up vector")
    x /= n
    y = np.cross(z, x)
    R = np.stack((x, y, z), -2)  # rows: camera axes in world coordinates
    t = -(R @ eye[..., None])[..., 0]
    f = 0.5 * height / np.tan(np.radians(fov_y_degrees) / 2)
    K = np.tile([f, f, width / 2.0, height / 2.0], (len(eye), 1))
    tt = lambda a: torch.as_tensor(a, dtype=dtype, device=device)  # noqa: E731
    return Camera(tt(K), tt(R), tt(t), height, width)


def to_usd(
    camera: Camera, index: int = 0, horizontal_aperture: float = USD_DEFAULT_HORIZONTAL_APERTURE
) -> dict[str, Any]:
    """One camera of the batch as USD camera attributes (see the module docstring).

    Returns focal_length, horizontal_aperture, vertical_aperture, horizontal_aperture_offset,
    vertical_aperture_offset (tenths of a scene unit) and camera_to_world (4, 4) in zooctl's
    column-vector convention (``Gf.Matrix4d(camera_to_world.T.tolist())`` for USD).
    """
    fx, fy, cx, cy = camera.intrinsics[index].detach().double().cpu().numpy()
    R = camera.rotation[index].detach().double().cpu().numpy()
    t = camera.translation[index].detach().double().cpu().numpy()
    W, H = camera.width, camera.height
    f = fx * horizontal_aperture / W
    va = f * H / fy
    c2w = np.eye(4)
    c2w[:3, :3] = R.T @ _FLIP
    c2w[:3, 3] = -R.T @ t
    return {
        "focal_length": float(f),
        "horizontal_aperture": float(horizontal_aperture),
        "vertical_aperture": float(va),
        "horizontal_aperture_offset": float((W / 2 - cx) * horizontal_aperture / W),
        "vertical_aperture_offset": float((cy - H / 2) * va / H),
        "camera_to_world": c2w,
    }


def from_usd(
    focal_length: float,
    horizontal_aperture: float,
    vertical_aperture: float,
    camera_to_world: Any,
    height: int,
    width: int,
    horizontal_aperture_offset: float = 0.0,
    vertical_aperture_offset: float = 0.0,
    dtype: torch.dtype = torch.float32,
) -> Camera:
    """A one-camera batch from USD camera attributes and the image size (inverse of `to_usd`).

    camera_to_world (4, 4) in zooctl's column-vector convention (a USD ``Gf.Matrix4d``
    transposed), rigid (no scale).
    """
    if min(focal_length, horizontal_aperture, vertical_aperture) <= 0:
        raise InputError("USD camera focal length and apertures must be positive")
    c2w = np.asarray(camera_to_world, dtype=np.float64)
    if c2w.shape != (4, 4):
        raise InputError(f"camera_to_world must be 4x4, got {c2w.shape}")
    R = (c2w[:3, :3] @ _FLIP).T
    t = -R @ c2w[:3, 3]
    fx = focal_length * width / horizontal_aperture
    fy = focal_length * height / vertical_aperture
    cx = width / 2 - horizontal_aperture_offset * width / horizontal_aperture
    cy = height / 2 + vertical_aperture_offset * height / vertical_aperture
    tt = lambda a: torch.as_tensor(np.asarray(a)[None], dtype=dtype)  # noqa: E731
    return Camera(tt([fx, fy, cx, cy]), tt(R), tt(t), height, width)


class _ToCameraKernel(torch.autograd.Function):
    """CPU kernel of `Camera.to_camera`: points (B, N, 3), rotation (B, 3, 3), translation (B, 3)."""

    @staticmethod
    def forward(ctx, points: Tensor, rotation: Tensor, translation: Tensor) -> Tensor:  # type: ignore[override]
        p, R, t = (x.detach().contiguous() for x in (points, rotation, translation))
        B, N = p.shape[:2]
        out = p.new_empty(B, N, 3)
        _kernels.kernel_for("to_camera_forward", p)(p, R, t, B, N, out)
        ctx.save_for_backward(p, R)
        return out

    @staticmethod
    def backward(ctx, g_pc: Tensor):  # type: ignore[override]
        p, R = ctx.saved_tensors
        B, N = p.shape[:2]
        g_pc = g_pc.to(p.dtype).contiguous()
        g_p, g_R, g_t = torch.empty_like(p), torch.empty_like(R), p.new_empty(B, 3)
        _kernels.kernel_for("to_camera_backward", p)(p, R, g_pc, B, N, g_p, g_R, g_t)
        return g_p, g_R, g_t


class _ProjectKernel(torch.autograd.Function):
    """CPU kernel of `Camera.project`: points (B, N, 3) and one camera per image -> xy, z."""

    @staticmethod
    def forward(ctx, points: Tensor, rotation: Tensor, translation: Tensor, intrinsics: Tensor):  # type: ignore[override]
        p, R, t, K = (x.detach().contiguous() for x in (points, rotation, translation, intrinsics))
        B, N = p.shape[:2]
        xy, z = p.new_empty(B, N, 2), p.new_empty(B, N)
        _kernels.kernel_for("project_forward", p)(p, R, t, K, B, N, xy, z)
        ctx.save_for_backward(p, R, t, K)
        return xy, z

    @staticmethod
    def backward(ctx, g_xy: Tensor, g_z: Tensor):  # type: ignore[override]
        p, R, t, K = ctx.saved_tensors
        B, N = p.shape[:2]
        g_xy, g_z = g_xy.to(p.dtype).contiguous(), g_z.to(p.dtype).contiguous()
        g_p, g_R, g_t, g_K = (
            torch.empty_like(p),
            torch.empty_like(R),
            torch.empty_like(t),
            torch.empty_like(K),
        )
        pose_grads = int(ctx.needs_input_grad[1] or ctx.needs_input_grad[2])
        _kernels.kernel_for("project_backward", p)(
            p, R, t, K, g_xy, g_z, B, N, pose_grads, g_p, g_R, g_t, g_K
        )
        return g_p, g_R if pose_grads else None, g_t if pose_grads else None, g_K
