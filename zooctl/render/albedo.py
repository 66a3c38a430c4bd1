"""Unlit colour renders of a mesh: its vertex colours or its UV texture as the camera sees them.

What a textured character looks like without any lighting: the benchmark compares it with the
frames a held-out camera saw (`zooctl.benchdata.appearance`), and tests check a bake by rendering
it back. Colours are linear RGB in [0, 1]; a texture is sRGB (PNG, as glTF's baseColorTexture)
sampled bilinearly with glTF's UV convention (u right, v down the image, texel centres at half
integers) and turned linear.
"""

from __future__ import annotations

import io

import numpy as np
import torch

from .camera import Camera


def decode_texture(png: bytes) -> np.ndarray:
    """(H, W, 3) float32 linear RGB of an sRGB PNG."""
    from PIL import Image

    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), np.float64) / 255.0
    return np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4).astype(np.float32)


@torch.no_grad()
def render_colours(
    vertices: np.ndarray,
    faces: np.ndarray,
    camera: Camera,
    vertex_colors: np.ndarray | None = None,
    uvs: np.ndarray | None = None,
    texture: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(B, H, W, 3) float32 linear colours and (B, H, W) bool coverage of ``vertices`` (B, V, 3)
    seen by ``camera`` (B cameras or one): ``texture`` (h, w, 3 linear, `decode_texture`) read at
    ``uvs`` (V, 2) when both are given, else ``vertex_colors`` (V, 3) interpolated, else grey."""
    from .raster import interpolate, rasterize

    v = torch.as_tensor(np.asarray(vertices, np.float32))
    B = v.shape[0]
    f = torch.as_tensor(np.asarray(faces), dtype=torch.long)
    cam = camera if camera.batch_size == B else camera.expand(B)
    frags = rasterize(v, f, cam)
    mask = frags.mask
    if texture is not None and uvs is not None:
        uv = torch.as_tensor(np.asarray(uvs, np.float32))[None].expand(B, -1, -1).contiguous()
        st = interpolate(uv, f, frags)  # (B, H, W, 2)
        tex = torch.as_tensor(np.asarray(texture, np.float32)).permute(2, 0, 1)[None].expand(B, -1, -1, -1)
        grid = (2 * st - 1).to(torch.float32)  # align_corners=False: uv 0 and 1 are the image's edges
        rgb = torch.nn.functional.grid_sample(
            tex, grid, mode="bilinear", padding_mode="border", align_corners=False
        ).permute(0, 2, 3, 1)
    else:
        col = (
            np.full((v.shape[1], 3), 0.5, np.float32)
            if vertex_colors is None
            else np.asarray(vertex_colors, np.float32)
        )
        rgb = interpolate(torch.as_tensor(col)[None].expand(B, -1, -1).contiguous(), f, frags)
    rgb = torch.where(mask[..., None], rgb, torch.zeros_like(rgb))
    return rgb.numpy().astype(np.float32), mask.numpy()
