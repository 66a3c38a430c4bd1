"""Differentiable renderers (batched PyTorch, CPU and CUDA) and the camera convention.

- `camera`: pinhole cameras; the one convention, and conversion to and from USD cameras.
- `soft`: SoftRas-style soft silhouettes with per-face screen windows.
- `splat`: area-weighted point splatting with a blur (the `fast` renderer): a cheap silhouette for
  large batches.
- `raster`: hard z-buffer with differentiable barycentrics; depth, face ids and optical flow.
- `windows`: the per-face screen windows (face, pixel pairs) that `soft` and `raster` share.
- `base`: the renderer interfaces and `get_renderer` (renderers by registered name).
- `preview`: shaded CPU previews (`zbuffer_mesh`: face ids of one mesh or a batch of its poses, no gradients).
- `benchmark`: timings behind `zooctl bench render|rig` and `bench/render.py`.
"""
