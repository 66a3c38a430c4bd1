"""Timing of renderers and articulation (forward + backward), shared by `zooctl bench` and `bench/`.

Scene: a UV sphere of radius 1 with about ``faces`` triangles, seen from 4 units by a 40 degree
camera, so its silhouette covers about 40% of the image; each batch element is jittered a little.
The loss is the sum of the output (flow: of the squared flow), so backward reaches every vertex.
"""

from __future__ import annotations

import platform
import statistics
import time
from typing import Any

import torch

from ..errors import MissingDependencyError, UsageError


def _device(name: str) -> torch.device:
    if name not in ("cpu", "cuda"):
        raise UsageError(f"unknown device {name!r}", hint="use cpu or cuda")
    if name == "cuda" and not torch.cuda.is_available():
        raise MissingDependencyError(
            "CUDA is not available in this PyTorch build or machine", hint="use --device cpu"
        )
    return torch.device(name)


def _sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def _time(step, device: torch.device, repeats: int, warmup: int) -> list[float]:
    for _ in range(warmup):
        step()
    _sync(device)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        step()
        _sync(device)
        times.append(time.perf_counter() - t0)
    return times


def machine() -> str:
    import os

    return f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, torch {torch.__version__}, {torch.get_num_threads()} threads"


def bench_render(
    renderer: str,
    faces: int = 2000,
    size: int = 128,
    batch: int = 8,
    device: str = "cpu",
    repeats: int = 5,
    warmup: int = 1,
    **options: Any,
) -> dict[str, Any]:
    """Median milliseconds per frame of forward + backward for one renderer (module docstring)."""
    from ..rig.synthetic import uv_sphere
    from .base import get_renderer, renders_flow
    from .camera import look_at

    if faces < 8 or size < 8 or batch < 1 or repeats < 1:
        raise UsageError("need --faces >= 8, --size >= 8, --batch >= 1, --repeats >= 1")
    dev = _device(device)
    gen = torch.Generator().manual_seed(0)
    v, f = uv_sphere(faces)
    base = torch.as_tensor(v)[None] + 0.05 * torch.randn(batch, 1, 3, generator=gen)
    verts = base.to(dev).requires_grad_(True)
    tri = torch.as_tensor(f, device=dev)
    cam = look_at([0.0, 0.0, 4.0], [0.0, 0.0, 0.0], size, size, fov_y_degrees=40.0, device=dev)
    mod = get_renderer(renderer, size, device=device, **options)  # any registered renderer
    if not renders_flow(mod):

        def step() -> None:
            verts.grad = None
            mod(verts, tri, cam).sum().backward()
    else:
        moved = (base + torch.tensor([0.03, 0.01, 0.0])).to(dev)

        def step() -> None:
            verts.grad = None
            mod(verts, tri, cam, moved + (verts - verts.detach()))["flow"].square().sum().backward()

    times = _time(step, dev, repeats, warmup)
    med = statistics.median(times)
    return {
        "renderer": renderer,
        "faces": int(len(f)),
        "size": size,
        "batch": batch,
        "device": device,
        "repeats": repeats,
        "ms_per_frame": 1000.0 * med / batch,
        "ms_per_batch": 1000.0 * med,
        "ms_per_frame_min": 1000.0 * min(times) / batch,
        "machine": machine() if dev.type == "cpu" else torch.cuda.get_device_name(dev),
    }


def bench_rig(
    vertices: int = 4000,
    joints: int = 50,
    frames: int = 8,
    device: str = "cpu",
    repeats: int = 5,
    warmup: int = 1,
    articulation: str = "casa",
) -> dict[str, Any]:
    """Median ms per frame of FK + skinning (the registered ``articulation`` model; casa: stretchable
    LBS), forward + backward, on a tube rig."""
    from ..rig.base import get_articulation_model
    from ..rig.rotations import axis_angle_to_quat
    from ..rig.synthetic import tube_asset

    if vertices < 64 or joints < 2 or frames < 1:
        raise UsageError("need --vertices >= 64, --joints >= 2, --frames >= 1")
    dev = _device(device)
    segments = 16
    rings = max(1, round((vertices / segments - 1) / joints))
    asset = tube_asset(bones=joints, rings_per_bone=rings, segments=segments, bone_length=0.2, radius=0.05)
    model = get_articulation_model(articulation, asset, device=dev, displacement=False)
    gen = torch.Generator().manual_seed(0)
    aa = (0.2 * torch.randn(frames, joints, 3, generator=gen)).to(dev).requires_grad_(True)

    def step() -> None:
        aa.grad = None
        model.zero_grad(set_to_none=True)
        model(axis_angle_to_quat(aa)).vertices.square().sum().backward()

    times = _time(step, dev, repeats, warmup)
    med = statistics.median(times)
    return {
        "benchmark": "fk+lbs" if articulation == "casa" else f"fk+{articulation}",
        "articulation": articulation,
        "vertices": asset.num_vertices,
        "joints": joints,
        "frames": frames,
        "device": device,
        "ms_per_frame": 1000.0 * med / frames,
        "ms_per_batch": 1000.0 * med,
        "machine": machine() if dev.type == "cpu" else torch.cuda.get_device_name(dev),
    }
