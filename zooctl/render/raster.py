"""Hard z-buffer rasterisation with differentiable barycentrics; depth, face ids and optical flow.

`rasterize` finds, for every pixel centre, the nearest face covering it (no gradient: a discrete
choice) and then recomputes that face's perspective-correct barycentrics *with* gradients with
respect to the vertices, so anything interpolated from them (depth, attributes, flow) is
differentiable almost everywhere, as in nvdiffrast / PyTorch3D.

Flow. `RasterFlow` renders the optical flow between two posed meshes with the same topology:
the surface point seen at pixel p at time t is ``X_t = sum_i b_i v_i^t`` (perspective-correct
barycentrics b), the same material point at t+1 is ``X_{t+1} = sum_i b_i v_i^{t+1}``, and the
flow is ``project_{t+1}(X_{t+1}) - p``. This is the exact flow for motions that are affine per
face (rigid motions in particular), rather than a screen-space interpolation of vertex flow.

Implementations. On CPU float tensors the z-buffer, the fragments (barycentrics and depth), the
interpolation and the flow projection run as C++ kernels (`zooctl.render._kernels`) with
hand-written backward passes; the z-buffer rounds exactly like the PyTorch path, so face ids and
masks are identical and values agree to float rounding. CUDA tensors, or machines without a C++
compiler, take the PyTorch path (same code with ``device="cuda"``).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from ..errors import InputError
from . import _kernels
from .camera import Camera
from .windows import (
    PairBudget,
    ScreenFaces,
    check_face_indices,
    face_pixel_pairs,
    face_windows_int32,
    padded,
    project_faces,
)

Tensor = torch.Tensor


@dataclass
class Fragments:
    """Per-pixel rasterisation result of a batch of B images.

    face_ids (B, H, W) long: index into the F faces, -1 for background; bary (B, H, W, 3)
    perspective-correct barycentrics (zero on background, differentiable); depth (B, H, W)
    camera-space z (0 on background, differentiable); mask (B, H, W) bool.
    """

    face_ids: Tensor
    bary: Tensor
    depth: Tensor
    mask: Tensor


def _screen_barycentrics(tri: Tensor, px: Tensor, py: Tensor) -> tuple[Tensor, Tensor]:
    """Screen-space barycentrics (N, 3) of points (N,) in triangles (N, 3, 2), and signed 2x area."""
    e = tri[:, 1:] - tri[:, :1]  # b - a, c - a
    area = e[:, 0, 0] * e[:, 1, 1] - e[:, 0, 1] * e[:, 1, 0]
    # w_i = (v_j - p) x (v_k - p) for (i, j, k) = (0, 1, 2), (1, 2, 0), (2, 0, 1), the three at once:
    # the same float steps as one expression each, in a few operators instead of thirty
    rel = tri - torch.stack((px, py), -1)[:, None, :]
    nxt, nxt2 = rel.roll(-1, 1), rel.roll(-2, 1)
    w = nxt[..., 0] * nxt2[..., 1] - nxt[..., 1] * nxt2[..., 0]
    safe = torch.where(area.abs() < 1e-20, torch.full_like(area, 1e-20), area)
    return w / safe[:, None], area


def _perspective_correct(lam: Tensor, depth: Tensor) -> tuple[Tensor, Tensor]:
    """Screen barycentrics (N, 3) and vertex depths (N, 3) -> 3D barycentrics (N, 3), depth (N,)."""
    inv = lam / depth
    s = inv.sum(-1, keepdim=True)
    return inv / s, 1.0 / s[:, 0]


@torch.no_grad()
def _zbuffer_kernel(sf: ScreenFaces, H: int, W: int) -> tuple[Tensor, Tensor] | None:
    """CPU kernel of `_zbuffer`: winner (B*H*W,) into B*F and face ids (B*H*W,) into F; None if n/a."""
    tri, depth = sf.tri.detach().contiguous(), sf.depth.detach().contiguous()
    kernel = _kernels.kernel_for("zbuffer", tri, depth)
    if kernel is None:
        return None
    win = face_windows_int32(sf, H, W, 0.0)
    n = sf.batch * H * W
    winner, face_ids = torch.empty(n, dtype=torch.long), torch.empty(n, dtype=torch.long)
    kernel(tri, depth, win, sf.batch, sf.num_faces, H, W, winner, torch.empty(n, dtype=tri.dtype), face_ids)
    return winner, face_ids


@torch.no_grad()
def _zbuffer(sf: ScreenFaces, H: int, W: int, budget: PairBudget | None = None) -> Tensor:
    """(B*H*W,) long: nearest covering face (index into B*F) per pixel centre, -1 if none; the
    pairs from ``budget`` when given (no read-back), else counted exactly."""
    pairs = face_pixel_pairs(sf, H, W, margin=0.0) if budget is None else budget.pairs(sf, H, W, 0.0)
    tri = padded(sf.tri.detach(), pairs)[pairs.face]
    lam, area = _screen_barycentrics(tri, pairs.px, pairs.py)
    inside = (lam >= 0).all(-1) & (area.abs() > 1e-12)  # never a padding pair's (no area)
    _, z = _perspective_correct(lam.clamp_min(0), padded(sf.depth.detach(), pairs, 1.0)[pairs.face])
    # Pairs outside their face are masked, not dropped: boolean indexing would make the host wait
    # for the device to learn how many are left (a GPU step then stalls at every call).
    pix = pairs.pixel
    z = torch.where(inside, z, torch.full_like(z, float("inf")))
    n = sf.batch * H * W  # and one more slot: a padding pair's (`Pairs`)
    zbuf = torch.full((n + 1,), float("inf"), dtype=z.dtype, device=z.device).scatter_reduce(
        0, pix, z, "amin"
    )
    win = inside & (z <= zbuf[pix])
    out = torch.full((n + 1,), -1, dtype=torch.long, device=z.device)
    return out.scatter_reduce(0, pix, torch.where(win, pairs.face, torch.full_like(pairs.face, -1)), "amax")[
        :n
    ]


class _FragmentsKernel(torch.autograd.Function):
    """CPU kernel: winner (B*H*W,) -> bary (B*H*W, 3), depth (B*H*W,), differentiable in tri, depth."""

    @staticmethod
    def forward(ctx, tri_all: Tensor, depth_all: Tensor, winner: Tensor, batch: int, height: int, width: int):  # type: ignore[override]
        tri, depth = tri_all.detach().contiguous(), depth_all.detach().contiguous()
        n = batch * height * width
        bary, zimg = tri.new_empty(n, 3), tri.new_empty(n)
        _kernels.kernel_for("fragments_forward", tri, depth)(
            tri, depth, winner, batch, height, width, bary, zimg
        )
        ctx.save_for_backward(tri, depth, winner)
        ctx.shape = (batch, height, width)
        return bary, zimg

    @staticmethod
    def backward(ctx, g_bary: Tensor, g_depth: Tensor):  # type: ignore[override]
        tri, depth, winner = ctx.saved_tensors
        B, H, W = ctx.shape
        g_bary = g_bary.to(tri.dtype).contiguous()
        g_depth = g_depth.to(tri.dtype).contiguous()
        grad_tri, grad_depth = torch.empty_like(tri), torch.empty_like(depth)
        _kernels.kernel_for("fragments_backward", tri)(
            tri, depth, winner, g_bary, g_depth, B, tri.shape[0] // B, H, W, grad_tri, grad_depth
        )
        return grad_tri, grad_depth, None, None, None, None


def rasterize(vertices: Tensor, faces: Tensor, camera: Camera, budget: PairBudget | None = None) -> Fragments:
    """Hard-rasterise vertices (B, V, 3) with faces (F, 3) long through ``camera`` (B or 1 cameras).

    Both windings are drawn (no back-face culling); ties in depth go to the higher face index.
    CPU tensors use the C++ kernels when they build, CUDA tensors the PyTorch path (same result);
    there a caller that rasterises every step passes its ``budget`` (`PairBudget`).
    """
    H, W = camera.height, camera.width
    sf = project_faces(vertices, faces, camera)
    shape = (sf.batch, H, W)
    found = _zbuffer_kernel(sf, H, W)
    if found is not None:
        winner, face_ids = found
    else:
        winner = _zbuffer(sf, H, W, budget)
        face_ids = torch.where(winner >= 0, winner % sf.num_faces, winner)
    if _kernels.kernel_for("fragments_forward", sf.tri, sf.depth, indices=(winner,)) is not None:
        bary_img, depth_img = _FragmentsKernel.apply(sf.tri, sf.depth, winner, sf.batch, H, W)
    else:
        # Every pixel, the background masked (not dropped: no wait for the device to count the
        # covered ones). A background pixel sees a unit triangle at depth 1 instead of a face,
        # so nothing it computes is inf or NaN, and its zero gradient stays zero. Gathers by
        # index_select: its backward adds atomically, where indexing's sorts the indices and sums
        # each run of repeats serially, and on CUDA the background's face 0 made one run of most
        # pixels (BENCHMARKS.md, "One NVIDIA H200").
        hit = winner >= 0
        pix = torch.arange(winner.shape[0], device=winner.device)
        face = winner.clamp_min(0)
        dt = sf.tri.dtype
        unit = torch.tensor([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], dtype=dt, device=winner.device)
        tri = torch.where(hit[:, None, None], sf.tri.index_select(0, face), unit)
        centre = torch.full((), 0.25, dtype=dt, device=winner.device)
        col = torch.where(hit, (pix % W).to(dt) + 0.5, centre)
        row = torch.where(hit, (torch.div(pix, W, rounding_mode="floor") % H).to(dt) + 0.5, centre)
        lam, _ = _screen_barycentrics(tri, col, row)
        depth_v = torch.where(hit[:, None], sf.depth.index_select(0, face), torch.ones_like(lam))
        bary, depth = _perspective_correct(lam, depth_v)
        bary_img = torch.where(hit[:, None], bary, torch.zeros_like(bary))
        depth_img = torch.where(hit, depth, torch.zeros_like(depth))
    return Fragments(
        face_ids.view(shape), bary_img.view(*shape, 3), depth_img.view(shape), (winner >= 0).view(shape)
    )


class _InterpolateKernel(torch.autograd.Function):
    """CPU kernel of `interpolate`: attributes (B, V, C), bary (B*H*W, 3) -> (B*H*W, C)."""

    @staticmethod
    def forward(ctx, attributes: Tensor, bary: Tensor, faces: Tensor, face_ids: Tensor) -> Tensor:  # type: ignore[override]
        attr, bary = attributes.detach().contiguous(), bary.detach().contiguous()
        B, V, C = attr.shape
        out = attr.new_empty(face_ids.numel(), C)
        _kernels.kernel_for("interpolate_forward", attr)(
            attr, faces, face_ids, bary, B, V, C, face_ids.numel() // B, out
        )
        ctx.save_for_backward(attr, bary, faces, face_ids)
        return out

    @staticmethod
    def backward(ctx, g_out: Tensor):  # type: ignore[override]
        attr, bary, faces, face_ids = ctx.saved_tensors
        B, V, C = attr.shape
        g_out = g_out.to(attr.dtype).contiguous()
        g_attr, g_bary = torch.empty_like(attr), torch.empty_like(bary)
        _kernels.kernel_for("interpolate_backward", attr)(
            attr, faces, face_ids, bary, g_out, B, V, C, face_ids.numel() // B, g_attr, g_bary
        )
        return g_attr, g_bary, None, None


def interpolate(attributes: Tensor, faces: Tensor, frags: Fragments) -> Tensor:
    """Interpolate per-vertex attributes (B, V, C) over the image: (B, H, W, C), zero on background."""
    B, H, W = frags.face_ids.shape
    if attributes.dtype == frags.bary.dtype:
        fid = frags.face_ids.reshape(-1).contiguous()
        f = faces.contiguous()
        if _kernels.kernel_for("interpolate_forward", attributes, frags.bary, indices=(f, fid)) is not None:
            check_face_indices(f, attributes.shape[1])
            if fid.numel() and int(fid.max()) >= f.shape[0]:
                raise InputError(f"fragments name face {int(fid.max())} but there are {f.shape[0]} faces")
            out = _InterpolateKernel.apply(attributes.expand(B, -1, -1), frags.bary.reshape(-1, 3), f, fid)
            return out.view(B, H, W, -1)
    fid = frags.face_ids.clamp_min(0)  # background reads face 0, then is zeroed by bary = 0
    vid = faces[fid]  # (B, H, W, 3)
    V, C = attributes.shape[-2:]
    rows = (torch.arange(B, device=vid.device)[:, None, None, None] * V + vid).reshape(-1)
    # index_select, as in `rasterize`: background pixels all read one vertex
    vals = attributes.expand(B, V, C).reshape(B * V, C).index_select(0, rows).view(B, H, W, 3, C)
    return (frags.bary[..., None] * vals).sum(-2)


class _FlowProjectKernel(torch.autograd.Function):
    """CPU kernel of RasterFlow's projection: pts (B*H*W, 3), intrinsics (B, 4) -> flow (B*H*W, 2)."""

    @staticmethod
    def forward(ctx, pts: Tensor, intrinsics: Tensor, face_ids: Tensor, height: int, width: int) -> Tensor:  # type: ignore[override]
        pts, intr = pts.detach().contiguous(), intrinsics.detach().contiguous()
        B = intr.shape[0]
        flow = pts.new_empty(pts.shape[0], 2)
        _kernels.kernel_for("flow_project_forward", pts)(pts, intr, face_ids, B, height, width, flow)
        ctx.save_for_backward(pts, intr, face_ids)
        ctx.size = (height, width)
        return flow

    @staticmethod
    def backward(ctx, g_flow: Tensor):  # type: ignore[override]
        pts, intr, face_ids = ctx.saved_tensors
        H, W = ctx.size
        g_flow = g_flow.to(pts.dtype).contiguous()
        g_pts, g_intr = torch.empty_like(pts), torch.empty_like(intr)
        _kernels.kernel_for("flow_project_backward", pts)(
            pts, intr, face_ids, g_flow, intr.shape[0], H, W, g_pts, g_intr
        )
        return g_pts, g_intr, None, None, None


class RasterFlow(nn.Module):
    """Optical flow of a surface moving from ``vertices`` to ``vertices_next`` (module docstring).

    forward(vertices (B, V, 3), faces (F, 3), camera, vertices_next (B, V, 3), camera_next=None)
    returns a dict: ``flow`` (B, H, W, 2) pixels (x right, y down; zero on background), ``mask``
    (B, H, W) bool, ``depth`` (B, H, W), ``face_ids`` (B, H, W) and ``bary`` (B, H, W, 3).
    """

    def __init__(self, image_size: int | tuple[int, int] | None = None, device: str = "cpu"):
        super().__init__()
        self.budget = PairBudget()  # the pair path's: no read-back a call (`PairBudget`)

    def forward(
        self,
        vertices: Tensor,
        faces: Tensor,
        camera: Camera,
        vertices_next: Tensor,
        camera_next: Camera | None = None,
    ) -> dict[str, Tensor]:
        frags = rasterize(vertices, faces, camera, self.budget)
        cam1 = (camera if camera_next is None else camera_next).expand(frags.face_ids.shape[0])
        # Interpolate the 3D camera-frame points at t+1, then project (exact for per-face affine motion).
        pts1 = interpolate(cam1.to_camera(vertices_next), faces, frags)  # (B, H, W, 3)
        return {
            "flow": _project_flow(pts1, cam1, frags),
            "mask": frags.mask,
            "depth": frags.depth,
            "face_ids": frags.face_ids,
            "bary": frags.bary,
        }


def _project_flow(pts1: Tensor, cam1: Camera, frags: Fragments) -> Tensor:
    """Flow (B, H, W, 2) from each pixel's centre to the projection of its point at t+1 ``pts1``
    (B, H, W, 3) through ``cam1``; zero on background. The C++ kernel where it applies."""
    B, H, W = frags.face_ids.shape
    fid = frags.face_ids.reshape(-1)
    if (
        _kernels.kernel_for("flow_project_forward", pts1, cam1.intrinsics, indices=(fid,)) is not None
        and cam1.intrinsics.dtype == pts1.dtype
    ):
        return _FlowProjectKernel.apply(pts1.reshape(-1, 3), cam1.intrinsics, fid, H, W).view(B, H, W, 2)
    k = cam1.intrinsics[:, None, None, :]
    z = pts1[..., 2]
    zs = torch.where(frags.mask, z, torch.ones_like(z))
    uv1 = pts1[..., :2] / zs[..., None] * k[..., :2] + k[..., 2:]
    cols = torch.arange(W, dtype=uv1.dtype, device=uv1.device) + 0.5
    rows = torch.arange(H, dtype=uv1.dtype, device=uv1.device) + 0.5
    grid = torch.stack(torch.broadcast_tensors(cols[None, :], rows[:, None]), -1)
    return torch.where(frags.mask[..., None], uv1 - grid, torch.zeros_like(uv1))
