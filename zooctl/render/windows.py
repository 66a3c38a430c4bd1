"""Per-face screen-space windows: the (face, pixel) pairs a rasteriser must look at.

Each face is projected, its bounding box grown by a margin (where its soft influence is not yet
negligible) and clipped to the image; the pixels inside become pairs. Work therefore follows the
pixels faces actually cover, not pixels x faces. Everything here is integer bookkeeping without
gradients; the renderers compute their differentiable terms on the pairs (PyTorch path) or
loop over each face's window directly (CPU kernels, `zooctl.render._kernels`).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from ..errors import InputError
from . import _kernels
from .camera import Camera

Tensor = torch.Tensor


@dataclass
class ScreenFaces:
    """Projected faces of a batch: tri (B*F, 3, 2) pixel positions, depth (B*F, 3), valid (B*F,)."""

    tri: Tensor
    depth: Tensor
    valid: Tensor
    batch: int
    num_faces: int


@dataclass
class Pairs:
    """Flattened (face, pixel) pairs: face (P,) into B*F, pixel (P,) into B*H*W, px/py (P,) centres.

    Pairs of a fixed capacity (`face_pixel_pairs`'s ``capacity``, `PairBudget`) end in padding:
    face B*F and pixel B*H*W, each one past the last (a caller gives its per-face and per-pixel
    tensors one more row, `padded`, and drops it), so padding touches no face or pixel of the
    picture; ``total`` (0-d, on the device) is how many pairs the windows held, padding not
    counted: where that was more than the capacity the pairs beyond it were left out."""

    face: Tensor
    pixel: Tensor
    px: Tensor
    py: Tensor
    total: Tensor | None = None


def check_face_indices(faces: Tensor, num_vertices: int) -> None:
    """Raise `InputError` unless faces is (F, 3) with entries in [0, num_vertices) (CPU kernels index raw memory)."""
    if faces.dim() != 2 or faces.shape[1] != 3:
        raise InputError(f"faces must be (F, 3), got {tuple(faces.shape)}")
    if faces.numel() and (int(faces.min()) < 0 or int(faces.max()) >= num_vertices):
        raise InputError(
            f"faces index vertices {int(faces.min())}..{int(faces.max())} but there are {num_vertices}",
            hint="pass faces that index the vertices tensor (0-based)",
        )


class _GatherFacesKernel(torch.autograd.Function):
    """CPU kernel: xy (B, V, 2), z (B, V) -> tri (B*F, 3, 2), depth (B*F, 3), valid (B*F,) bool."""

    @staticmethod
    def forward(ctx, xy: Tensor, z: Tensor, faces: Tensor, near: float):  # type: ignore[override]
        xy, z = xy.detach().contiguous(), z.detach().contiguous()
        B, V = z.shape
        F = faces.shape[0]
        tri, depth = xy.new_empty(B * F, 3, 2), xy.new_empty(B * F, 3)
        valid = torch.empty(B * F, dtype=torch.uint8)
        _kernels.kernel_for("gather_faces", xy, z)(xy, z, faces, B, V, F, near, tri, depth, valid)
        valid = valid.bool()
        ctx.mark_non_differentiable(valid)
        ctx.save_for_backward(faces)
        ctx.shape = (B, V)
        return tri, depth, valid

    @staticmethod
    def backward(ctx, g_tri: Tensor, g_depth: Tensor, _g_valid: Tensor):  # type: ignore[override]
        (faces,) = ctx.saved_tensors
        B, V = ctx.shape
        g_tri, g_depth = g_tri.contiguous(), g_depth.to(g_tri.dtype).contiguous()
        g_xy, g_z = g_tri.new_empty(B, V, 2), g_tri.new_empty(B, V)
        _kernels.kernel_for("gather_faces_backward", g_tri, g_depth)(
            g_tri, g_depth, faces, B, V, faces.shape[0], g_xy, g_z
        )
        return g_xy, g_z, None, None


def project_faces(vertices: Tensor, faces: Tensor, camera: Camera) -> ScreenFaces:
    """vertices (B, V, 3) world, faces (F, 3) long -> `ScreenFaces` (differentiable tri and depth)."""
    B = vertices.shape[0]
    cam = camera.expand(B)
    xy, z = cam.project(vertices)
    if xy.dtype == z.dtype and _kernels.kernel_for("gather_faces", xy, z, indices=(faces,)) is not None:
        check_face_indices(faces, vertices.shape[1])
        tri, depth, valid = _GatherFacesKernel.apply(xy, z, faces.contiguous(), float(cam.near))
        return ScreenFaces(tri, depth, valid, B, int(faces.shape[0]))
    corners = faces.reshape(-1)  # index_select: a backward without sorting (`raster.rasterize`)
    tri = xy.index_select(1, corners).reshape(-1, 3, 2)
    depth = z.index_select(1, corners).reshape(-1, 3)
    # min() propagates NaN, so this equals (depth > near).all(-1), in one reduction instead of two.
    valid = (depth.min(-1).values > cam.near) & torch.isfinite(tri.reshape(-1, 6)).all(-1)
    return ScreenFaces(tri, depth, valid, B, int(faces.shape[0]))


@torch.no_grad()
def face_windows(sf: ScreenFaces, height: int, width: int, margin: float) -> Tensor:
    """(B*F, 4) long inclusive pixel bounds x0, y0, x1, y1 of each face's box grown by ``margin``.

    A pixel (row i, column j) is in the window when its centre (j + 0.5, i + 0.5) is within
    ``margin`` of the face's bounding box; clipped to the image. Invalid faces and faces off the
    image get an empty window (x1 < x0 or y1 < y0).
    """
    tri = sf.tri.detach()
    lo = tri.min(1).values - margin - 0.5  # centre of pixel j is j + 0.5
    hi = tri.max(1).values + margin - 0.5
    size = torch.tensor([width, height], dtype=tri.dtype, device=tri.device)  # x and y at once
    first = lo.ceil().clamp(torch.zeros_like(size), size).long()  # x0, y0
    last = hi.floor().clamp(torch.full_like(size, -1.0), size - 1).long()  # x1, y1
    win = torch.cat((first, last), -1)
    # Invalid faces may have NaN corners (garbage after .long()): give them a fixed empty window.
    empty = torch.tensor([0, 0, -1, -1], dtype=win.dtype, device=win.device)
    return torch.where(sf.valid[:, None], win, empty)


@torch.no_grad()
def face_windows_int32(sf: ScreenFaces, height: int, width: int, margin: float) -> Tensor:
    """`face_windows` as a contiguous (B*F, 4) int32 tensor, what the CPU kernels read; on CPU
    float tensors computed by a kernel (the same float steps, so the same windows)."""
    tri = sf.tri.detach()
    kernel = _kernels.kernel_for("face_windows", tri)
    if kernel is None or sf.valid.dtype != torch.bool:
        return face_windows(sf, height, width, margin).to(torch.int32).contiguous()
    win = torch.empty(tri.shape[0], 4, dtype=torch.int32)
    valid = sf.valid.contiguous().view(torch.uint8)
    kernel(tri.contiguous(), valid, tri.shape[0], height, width, float(margin), win)
    return win


def padded(rows: Tensor, pairs: Pairs, fill: float = 0.0) -> Tensor:
    """``rows`` (N, ...) with one more row of ``fill`` where ``pairs`` may hold padding (`Pairs`),
    which indexes that row; the rows themselves otherwise."""
    if pairs.total is None:
        return rows
    return torch.cat((rows, rows.new_full((1, *rows.shape[1:]), fill)))


@torch.no_grad()
def face_pixel_pairs(
    sf: ScreenFaces, height: int, width: int, margin: float, capacity: int | None = None
) -> Pairs:
    """Every (face, pixel) pair with the pixel centre within ``margin`` px of the face's box.

    The number of pairs is read back from the device (the host waits for it) unless ``capacity``
    is given: then exactly ``capacity`` pairs, the same pairs in the same order as without it
    followed by padding (`Pairs`), and nothing is read back."""
    win = face_windows(sf, height, width, margin)
    x0, y0 = win[:, 0], win[:, 1]
    w = (win[:, 2] - x0 + 1).clamp_min(0)
    h = (win[:, 3] - y0 + 1).clamp_min(0)
    counts = w * h
    dev = win.device
    if capacity is None:
        total = int(counts.sum())
        face = torch.repeat_interleave(torch.arange(len(counts), device=dev), counts, output_size=total)
        start = torch.cumsum(counts, 0) - counts
        local = torch.arange(total, device=dev) - start[face]
        pad, count = None, None
    else:
        # The counts cut at the capacity, and one more "face" holding the padding, so that they
        # sum to the capacity exactly: the output's size is known without a read-back.
        end = torch.cumsum(counts, 0)
        count = end[-1]
        kept_end = end.clamp_max(capacity)
        kept = torch.diff(kept_end, prepend=end.new_zeros(1))
        rest = (capacity - count).clamp_min(0).reshape(1)
        face = torch.repeat_interleave(
            torch.arange(len(counts) + 1, device=dev), torch.cat((kept, rest)), output_size=capacity
        )
        pad = face == len(counts)
        start = kept_end - kept
        local = torch.arange(capacity, device=dev) - torch.cat((start, start.new_zeros(1)))[face]
    # the windows' entries of each pair's face (padding reads the last face's: its pixel is replaced)
    at = face if pad is None else face.clamp_max(len(counts) - 1)
    wf = w[at].clamp_min(1)
    col = x0[at] + local % wf
    row = y0[at] + torch.div(local, wf, rounding_mode="floor")
    b = torch.div(at, sf.num_faces, rounding_mode="floor")
    pixel = (b * height + row) * width + col
    if pad is not None:
        pixel = pixel.masked_fill(pad, sf.batch * height * width)
    dt = sf.tri.dtype
    return Pairs(face, pixel, col.to(dt) + 0.5, row.to(dt) + 0.5, count)


class PairBudget:
    """A fixed number of (face, pixel) pairs for one renderer's calls, so that a call waits for
    nothing on the device; while ``on`` is False (the default, `FitConfig.pair_budget`) every
    call counts its pairs exactly instead.

    The first call counts its pairs (one read) and sets the budget to twice that. Later calls get
    the budget's pairs (`face_pixel_pairs`'s ``capacity``), and after 4, 8 and then every 16
    calls their counts are read back together (one read) and the budget set to ``headroom``
    times the largest plus its growth since the last read: soon where the body grows or shrinks
    at the start of a stage, and over the spread of the windows' frames later. A call whose
    windows held more pairs than the budget leaves the rest out and counts in ``overflows``;
    ``reads`` counts the reads back."""

    def __init__(self, every: int = 16, headroom: float = 1.25, quantum: int = 4096) -> None:
        self.every, self.headroom, self.quantum = every, headroom, quantum
        self.capacity: int | None = None
        self.on = False
        self.overflows = self.reads = 0
        self._pending: list[tuple[Tensor, int]] = []  # each call's count and capacity
        self._next = 4
        self._last = 0  # the largest count at the last read

    def _size(self, count: float) -> int:
        return max(self.quantum, -(-int(count) // self.quantum) * self.quantum)

    def pairs(self, sf: ScreenFaces, height: int, width: int, margin: float) -> Pairs:
        if not self.on or (sf.tri.device.type == "cpu" and _kernels.enabled()):
            # On a CPU the pair path runs because no compiler built the kernels: nothing to wait
            # for, and counting exactly is cheaper. With the kernels turned off (tests,
            # `bench/step.py --torch-path`) the CPU runs what a device runs, budget included.
            return face_pixel_pairs(sf, height, width, margin)
        if self.capacity is None:
            p = face_pixel_pairs(sf, height, width, margin)
            self._last = len(p.face)
            self.capacity = self._size(2 * self._last)
            self.reads += 1
            return p
        p = face_pixel_pairs(sf, height, width, margin, capacity=self.capacity)
        assert p.total is not None
        self._pending.append((p.total, self.capacity))
        if len(self._pending) >= self._next:
            self.check()
        return p

    def check(self) -> None:
        """Read the counts of the calls since the last check (one read) and set the budget."""
        if not self._pending or self.capacity is None:
            return
        counts = torch.stack([t for t, _ in self._pending]).tolist()
        self.overflows += sum(c > cap for c, (_, cap) in zip(counts, self._pending, strict=True))
        self._pending = []
        self.reads += 1
        self._next = min(2 * self._next, self.every)
        most = max(counts)
        growth = max(0, most - self._last)  # since the last read: a body growing keeps growing
        self._last = most
        self.capacity = self._size(self.headroom * (most + growth))
