"""An example of every component kind a third party can add to zooctl, each small but real:

- importer ``toyrig``: the `.toyrig` format, ``{"bones": N, "length": L, "radius": R, "fps": F}`` in
  JSON. It builds a tube of ``N`` bones along +Y with smooth two-bone skinning weights and a
  ``wiggle`` clip (each joint swings about Z, phase-shifted along the chain);
- renderer ``pointsplat``: a differentiable silhouette made of one Gaussian splat per vertex
  (``zooctl fit --renderer pointsplat``);
- articulation model ``rigid``: rigid skinning, every vertex follows its strongest bone only
  (``zooctl fit --articulation rigid``);
- exporter ``ply``: the mesh, posed at the first frame of the first clip, as ASCII PLY
  (``zooctl bank export NAME --format ply``);
- segmenter ``backdrop``: an animal filmed against a plain backdrop (a studio, a tank, the sky):
  pixels whose colour is far from the frame border's median colour
  (``zooctl video add clip.mp4 --segmenter backdrop --seg-option tolerance=40``);
- flow estimator ``farneback``: OpenCV's Farneback dense optical flow
  (``zooctl video add clip.mp4 --flow farneback``);
- a command, ``zooctl toyrig``.

Heavy imports (torch, zooctl's model code) stay inside the factories, so ``zooctl --help`` stays fast.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import typer

from zooctl.components import ComponentSpec, ExporterSpec, ImporterSpec
from zooctl.errors import InputError
from zooctl.plugins import hookimpl


def load_toyrig(path: Path, name: str):
    import numpy as np

    from zooctl.asset import Clip, RiggedAsset

    try:
        spec = json.loads(Path(path).read_text())
        n = int(spec["bones"])
        length = float(spec.get("length", 1.0))
        radius = float(spec.get("radius", 0.1))
        fps = float(spec.get("fps", 30))
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise InputError(
            f"{path}: not a valid .toyrig file ({exc})", hint='expected JSON like {"bones": 4}'
        ) from None
    if not (1 <= n <= 64) or length <= 0 or radius <= 0:
        raise InputError(f"{path}: bones must be 1..64 and length, radius positive")
    seg = length / n
    rings, around = 4 * n + 1, 12
    ys = np.linspace(0, length, rings)
    ang = np.linspace(0, 2 * math.pi, around, endpoint=False)
    verts = np.array([[radius * math.cos(a), y, radius * math.sin(a)] for y in ys for a in ang], np.float32)
    faces = []
    for r in range(rings - 1):
        for k in range(around):
            a, b = r * around + k, r * around + (k + 1) % around
            c, d = a + around, b + around
            faces += [[a, c, b], [b, c, d]]
    # each vertex blends the bone it lies on with the nearest neighbouring bone
    t = np.clip(verts[:, 1] / seg - 0.5, 0, n - 1)
    j0 = np.floor(t).astype(np.int32)
    j1 = np.minimum(j0 + 1, n - 1)
    w1 = (t - j0).astype(np.float32)
    joints = np.stack([j0, j1], 1)
    weights = np.stack([1 - w1, w1], 1)
    same = j0 == j1
    weights[same] = [1, 0]
    order = np.argsort(-weights, 1)
    joints = np.take_along_axis(joints, order, 1)
    weights = np.take_along_axis(weights, order, 1)
    parents = np.arange(-1, n - 1, dtype=np.int32)
    rest = np.tile(np.eye(4), (n, 1, 1))
    rest[1:, 1, 3] = seg
    ibm = np.tile(np.eye(4), (n, 1, 1))
    ibm[:, 1, 3] = -seg * np.arange(n)
    T = int(fps)
    ph = np.linspace(0, 2 * math.pi, T, endpoint=False)[:, None] - 0.6 * np.arange(n)[None]
    half = 0.25 * np.sin(ph) / 2
    rot = np.zeros((T, n, 4), np.float32)
    rot[..., 0], rot[..., 3] = np.cos(half), np.sin(half)
    clip = Clip(
        "wiggle",
        fps,
        rot,
        np.repeat(rest[None, :, :3, 3], T, 0).astype(np.float32),
        np.ones((T, n, 3), np.float32),
    )
    return RiggedAsset(
        name=name,
        vertices=verts,
        faces=np.array(faces, np.int32),
        joint_names=[f"bone{i}" for i in range(n)],
        parents=parents,
        rest_local=rest,
        inverse_bind=ibm,
        skin_joints=joints.astype(np.int32),
        skin_weights=weights.astype(np.float32),
        clips={"wiggle": clip},
        meta={
            "source": str(path),
            "source_format": "toyrig",
            "units": "m",
            "meters_per_unit": 1.0,
            "up_axis": "Y",
        },
    ).validate()


def pointsplat(image_size, device="cpu", sigma=1.0, opacity=0.5, **options):
    """A silhouette renderer: vertices (B, V, 3), faces (F, 3), camera -> (B, H, W) in [0, 1].

    Each vertex projects to a Gaussian of ``sigma`` pixels with peak ``opacity``; a pixel's
    coverage is ``1 - prod_i (1 - a_i)``. Faces are unused: dense meshes need no triangles here.
    """
    import torch

    def render(vertices, faces, camera):
        H, W = camera.height, camera.width
        xy, _ = camera.project(vertices)  # (B, V, 2) pixels
        ys = torch.arange(H, dtype=xy.dtype, device=xy.device) + 0.5
        xs = torch.arange(W, dtype=xy.dtype, device=xy.device) + 0.5
        dx = (xs[None, None, :] - xy[..., 0:1]) ** 2  # (B, V, W)
        dy = (ys[None, None, :] - xy[..., 1:2]) ** 2  # (B, V, H)
        a = opacity * torch.exp(-(dy[..., :, None] + dx[..., None, :]) / (2 * sigma**2))  # (B, V, H, W)
        return 1.0 - torch.exp(torch.log1p(-a.clamp(max=0.999)).sum(1))

    return render


def rigid_model(asset, device="cpu", **options):
    """`ArticulatedModel` with rigid skinning: each vertex moves with its strongest bone only."""
    import torch

    from zooctl.rig.model import ArticulatedModel
    from zooctl.rig.skinning import linear_blend_skinning

    def rigid_skinning(points, mats, bones, weights, stretch=None, endpoint=None):
        hard = torch.nn.functional.one_hot(weights.argmax(-1), weights.shape[-1]).to(weights.dtype)
        return linear_blend_skinning(points, mats, bones, hard, stretch, endpoint)

    class RigidModel(ArticulatedModel):
        skinning = staticmethod(rigid_skinning)

    return RigidModel(asset, device=device, **options)


def save_ply(asset, path, clips=None, **options):
    """The mesh posed at the first frame of the first chosen clip (rest pose without clips)."""
    from zooctl.store.fs import write_bytes_atomic

    names = list(asset.clips) if clips is None else list(clips)
    verts = asset.pose(names[0], 0) if names else asset.pose()
    lines = ["ply", "format ascii 1.0", f"element vertex {len(verts)}", "property float x"]
    lines += ["property float y", "property float z", f"element face {len(asset.faces)}"]
    lines += ["property list uchar int vertex_indices", "end_header"]
    lines += [f"{x:.6f} {y:.6f} {z:.6f}" for x, y, z in verts]
    lines += [f"3 {a} {b} {c}" for a, b, c in asset.faces]
    write_bytes_atomic(Path(path), ("\n".join(lines) + "\n").encode())  # temporary, then os.replace


class BackdropSegmenter:
    """Foreground = colour farther than ``tolerance`` (0-255 units) from the median colour of the
    frame's border pixels; the largest connected region is kept."""

    def __init__(self, tolerance: float = 40.0, border: int = 4) -> None:
        self.tolerance, self.border = float(tolerance), int(border)
        if self.tolerance <= 0 or self.border < 1:
            raise InputError("backdrop: tolerance must be positive and border at least 1 pixel")

    def segment(self, frames, box=None, progress=None):
        """(T, H, W, 3) uint8 -> (T, H, W) bool."""
        import cv2
        import numpy as np

        b = self.border
        out = np.zeros(frames.shape[:3], bool)
        for t, img in enumerate(frames):
            f = img.astype(np.float32)
            ring = np.concatenate([f[:b].reshape(-1, 3), f[-b:].reshape(-1, 3)])
            ring = np.concatenate([ring, f[:, :b].reshape(-1, 3), f[:, -b:].reshape(-1, 3)])
            fg = (np.linalg.norm(f - np.median(ring, 0), axis=-1) > self.tolerance).astype(np.uint8)
            n, labels, stats, _ = cv2.connectedComponentsWithStats(fg, connectivity=8)
            if n > 1:
                out[t] = labels == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
            if progress is not None:
                progress(t + 1, len(frames))
        return out


class FarnebackFlow:
    """OpenCV's Farneback flow (a dense polynomial-expansion method; DIS is the built-in)."""

    def __init__(self, levels: int = 3, winsize: int = 15) -> None:
        self.levels, self.winsize = int(levels), int(winsize)

    def flow(self, frame_a, frame_b):
        """(H, W, 3) uint8 twice -> (H, W, 2) float32: pixel displacement from a to b."""
        import cv2
        import numpy as np

        a, b = (cv2.cvtColor(f, cv2.COLOR_RGB2GRAY) for f in (frame_a, frame_b))
        fl = cv2.calcOpticalFlowFarneback(a, b, None, 0.5, self.levels, self.winsize, 3, 5, 1.2, 0)
        return fl.astype(np.float32)


@hookimpl
def register_segmenters(register):
    register(
        ComponentSpec(
            "segmenter",
            "backdrop",
            lambda **options: BackdropSegmenter(**options),
            "animal against a plain backdrop (example plugin)",
        )
    )


@hookimpl
def register_flow_estimators(register):
    register(
        ComponentSpec(
            "flow_estimator",
            "farneback",
            lambda **options: FarnebackFlow(**options),
            "OpenCV Farneback dense flow (example plugin)",
        )
    )


@hookimpl
def register_renderers(register):
    register(
        ComponentSpec("renderer", "pointsplat", pointsplat, "Gaussian splat per vertex (example plugin)")
    )


@hookimpl
def register_articulation_models(register):
    register(
        ComponentSpec(
            "articulation_model", "rigid", rigid_model, "rigid skinning: one bone per vertex (example)"
        )
    )


@hookimpl
def register_exporters(register):
    register(ExporterSpec("ply", ("ply",), save_ply, "posed mesh as ASCII PLY (example plugin)", (".ply",)))


@hookimpl
def register_importers(register):
    register(ImporterSpec("toyrig", (".toyrig",), load_toyrig, "toy JSON bone chains (example plugin)"))


@hookimpl
def register_commands(cli):
    @cli.command("toyrig")
    def toyrig(
        name: str = typer.Argument(..., help="A label stored in the file."),
        out: Path = typer.Option(..., "-o", "--out", help="Where to write the .toyrig file."),
        bones: int = typer.Option(4, help="Number of bones."),
    ) -> None:
        """Write an example .toyrig file (from the zooctl-example plugin)."""
        out.write_text(json.dumps({"label": name, "bones": bones, "length": 1.0, "radius": 0.1, "fps": 30}))
        typer.echo(f"wrote {out}")
