"""Video preprocessing: decoding, segmentation, optical flow and previews.

Every array here is numpy: frames (T, H, W, 3) uint8 RGB, masks (T, H, W) bool, flow (H, W, 2) float32
pixel displacements (x, y). The HDF5 store that keeps them is `zooctl.store.videos`.
"""
