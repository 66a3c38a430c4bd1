"""Differentiable articulation (CASA section 3.1 and supplement D) in batched PyTorch.

- `rotations`: quaternion / matrix / 6D / axis-angle conversions over ``...`` batch dimensions.
- `kinematics`: forward kinematics over an asset's joint tree, with per-bone length scales.
- `skinning`: stretchable bones and linear blend skinning with weights kept on the simplex.
- `displacement`: the vertex displacement field (a coordinate MLP) and global scale.
- `priors`: motion smoothness, symmetry (Householder plane found from the template), bone lengths.
- `model`: `ArticulatedModel`, an ``nn.Module`` tying them together for one `RiggedAsset`.

Everything runs on CPU and CUDA unchanged (pass ``device="cuda"``).
"""
