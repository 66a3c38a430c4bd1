"""Motion prior (Ponymation section 3.3 / appendix B), for any skeleton in the bank.

- `skeleton`: `Skeleton`, the skeleton description a motion model sees (rest pose, tree, scale).
- `dataset`: motion sequences from bank clips (and, later, fits), resampled, cut into windows.
- `model`: `MotionVAE`, the spatio-temporal transformer VAE over padded bone tokens (the paper's),
  and `TrajectoryVAE`, one token per bone holding its whole window (the CPU default).
- `losses`: rotation, posed-joint (through `zooctl.rig` forward kinematics) and KL (free bits) terms.
- `train`: the training loop (time budget, reconstruction warm-up then KL annealing, loss-curve PNG).
- `prior`: `PonymationPrior`, the object the ``ponymation`` motion-prior plugin returns
  (``fit``, ``save``, ``sample``), with chained sampling and optimised transition latents.
- `latents`: where samples draw z: each skeleton's aggregate posterior from its training windows;
  `temperature`: the temperature samples use by default; `calibrate`: its calibration.
- `baselines`: nearest-clip retrieval and a per-skeleton Gaussian/PCA prior; `pca_prior`: the
  latter as a trainable, stored, sampleable prior (``pca`` plugin).
- `metrics`: reconstruction error, motion Chamfer distance, diversity, smoothness, foot sliding,
  and what catches a statue: per-joint amplitude and speed ratios, gait periodicity, seam jumps.

Motion representation: per-bone *local rotations relative to the rest rotation* (``R_local =
R_rest @ R_delta``) in the continuous 6D form (Zhou et al. 2019), so the identity is the rest pose
for every skeleton. Root translation is excluded, as in Ponymation: sampled clips keep every joint
at its rest translation and scale, and the root's rotation is modelled like any other bone.
"""
