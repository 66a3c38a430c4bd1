"""The vertex displacement field of CASA eq. 3: ``v'_i = u v_i + V_theta(u p_i)``.

``V_theta`` is a four-layer coordinate MLP over (optionally positionally encoded) canonical
positions; its last layer starts at zero so a fresh field displaces nothing. ``u`` is a global
scale, stored as its logarithm so it stays positive.
"""

from __future__ import annotations

import math

import torch
from torch import nn

Tensor = torch.Tensor


def positional_encoding(x: Tensor, num_freqs: int) -> Tensor:
    """(..., C) -> (..., C * (1 + 2 * num_freqs)): x, sin(2^i pi x), cos(2^i pi x)."""
    if num_freqs <= 0:
        return x
    freqs = (2.0 ** torch.arange(num_freqs, dtype=x.dtype, device=x.device)) * math.pi
    xf = x[..., None, :] * freqs[:, None]  # (..., L, C)
    return torch.cat((x, xf.sin().flatten(-2), xf.cos().flatten(-2)), -1)


class DisplacementField(nn.Module):
    """``V_theta``: canonical points (..., N, 3) -> displacements (..., N, 3).

    ``extent`` (model units, e.g. the template's bounding-box diagonal) normalises the input so
    the encoding frequencies mean the same for every asset; outputs are in model units too.
    """

    def __init__(self, extent: float = 1.0, hidden: int = 128, layers: int = 4, num_freqs: int = 0):
        super().__init__()
        if layers < 2:
            raise ValueError("the displacement MLP needs at least 2 layers")
        self.extent = float(extent)
        self.num_freqs = int(num_freqs)
        dims = [3 * (1 + 2 * self.num_freqs)] + [hidden] * (layers - 1) + [3]
        mods: list[nn.Module] = []
        for i in range(layers):
            mods.append(nn.Linear(dims[i], dims[i + 1]))
            if i < layers - 1:
                mods.append(nn.Softplus(beta=10.0))
        self.mlp = nn.Sequential(*mods)
        nn.init.zeros_(self.mlp[-1].weight)
        nn.init.zeros_(self.mlp[-1].bias)

    def forward(self, points: Tensor) -> Tensor:
        x = positional_encoding(points / self.extent, self.num_freqs)
        return self.mlp(x) * self.extent
