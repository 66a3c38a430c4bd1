"""A UV atlas for a character without usable UVs, so that the fit's colour bake can write a
texture instead of vertex colours.

The bank's templates are low-poly (a few thousand faces, most of them flat-shaded): vertex colours
give one colour per face corner, a texture gives the fur's pattern inside each face. The charts
and their packing come from xatlas (MIT): charts grow over faces that share an edge or are
coplanar, each chart is flattened with little stretch and packed into one square texture with a
gutter of a few texels (bilinear filtering reads no neighbouring chart). A vertex on a chart seam
is split in two; every per-vertex array of the character follows the split.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..asset import RiggedAsset

PADDING = 2  # texels between charts at the texture's size
_TRIES = 8  # texel densities tried, each 0.9x the last, until every chart fits one texture


def atlas_uvs(
    vertices: np.ndarray, faces: np.ndarray, size: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(vertex map (V',) into ``vertices``, faces (F, 3) into the new vertices, UVs (V', 2) in the
    unit square, v down as glTF's) of a chart atlas packed into one ``size`` x ``size`` texture, or
    None when xatlas is not installed or cannot place the mesh in one texture."""
    try:
        import xatlas
    except ImportError:
        return None
    v = np.ascontiguousarray(vertices, np.float32)
    f = np.ascontiguousarray(faces, np.uint32)
    tri = v[f].astype(np.float64)
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum()
    if not area > 0:
        return None
    density = 0.85 * size / np.sqrt(area)  # texels per unit length that would fill the square
    for _ in range(_TRIES):
        at = xatlas.Atlas()
        at.add_mesh(v, f)
        pack = xatlas.PackOptions()
        pack.resolution = size
        pack.padding = PADDING
        pack.bilinear = True
        pack.texels_per_unit = float(density)
        at.generate(xatlas.ChartOptions(), pack)
        if at.atlas_count == 1 and at.width <= size and at.height <= size:
            vmap, new_faces, uv = at[0]
            # Texel units of the packed square (xatlas's UVs are normalised to its own width/height).
            uv = uv.astype(np.float64) * np.array([at.width, at.height]) / size
            return vmap.astype(np.int64), new_faces.astype(np.int32).reshape(-1, 3), uv.astype(np.float32)
        density *= 0.9
    return None


def with_atlas(asset: RiggedAsset, size: int) -> tuple[RiggedAsset, np.ndarray] | None:
    """``asset`` with generated UVs (`atlas_uvs` of its bind-pose mesh; seam vertices split, its
    old UVs and texture dropped) and the map from its new vertices to the old ones, or None."""
    made = atlas_uvs(asset.vertices, asset.faces, size)
    if made is None:
        return None
    vmap, faces, uv = made
    out = dataclasses.replace(
        asset,
        vertices=asset.vertices[vmap],
        faces=faces,
        skin_joints=asset.skin_joints[vmap],
        skin_weights=asset.skin_weights[vmap],
        vertex_colors=None if asset.vertex_colors is None else asset.vertex_colors[vmap],
        uvs=uv,
        texture_png=None,
    )
    return out, vmap
