"""Differentiable renderers (batched PyTorch, CPU and CUDA) and the camera convention.

- `camera`: pinhole cameras; the one convention, and conversion to and from USD cameras.
- `soft`: SoftRas-style soft silhouettes with per-face screen windows.
- `fast`: area-weighted point splatting with a blur: a cheap silhouette for large batches.
- `raster`: hard z-buffer with differentiable barycentrics; depth, face ids and optical flow.
- `windows`: the per-face screen windows (face, pixel pairs) that `soft` and `raster` share.
- `benchmark`: timings behind `zooctl bench render|rig` and `bench/render.py`.
"""
