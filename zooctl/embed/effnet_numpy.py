"""EfficientNet-Lite0 features in numpy: the same network as `zooctl.embed.effnet`, without torch.

A first `zooctl bank search` of a video embeds about 8 crops; importing torch for that took longer
than the embedding itself (BENCHMARKS.md, Retrieval). This forward pass reads the same shipped
weights (`zooctl.embed.state_dict`, no torch), folds every batch norm into the convolution before
it, and runs in NHWC float32: 1x1 convolutions are matrix products, depthwise ones a sum of
k * k shifted slices, the 3x3 stem an im2col product. It matches the torch model's features to
about 1e-5 (tests/test_embed_effnet.py) and is what the ``effnet`` embedder uses on the CPU.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

# The architecture constants live in one place; importing them does not import torch.
from .effnet_arch import BN_EPS, HEAD_CHANNELS, LITE0_STAGES


@dataclass
class _Conv:
    """A convolution with its batch norm folded in: weight (Cout, Cin*k*k) or depthwise (k, k, C)."""

    weight: np.ndarray
    bias: np.ndarray
    kernel: int
    stride: int


@dataclass
class _Block:
    expand: _Conv | None
    depthwise: _Conv
    project: _Conv
    skip: bool


def _fold(sd: dict[str, np.ndarray], conv: str, bn: str) -> tuple[np.ndarray, np.ndarray]:
    w = sd[f"{conv}.weight"].astype(np.float32)
    scale = sd[f"{bn}.weight"] / np.sqrt(sd[f"{bn}.running_var"] + BN_EPS)
    bias = sd[f"{bn}.bias"] - sd[f"{bn}.running_mean"] * scale
    return (w * scale[:, None, None, None]).astype(np.float32), bias.astype(np.float32)


def _pointwise(sd, conv: str, bn: str) -> _Conv:
    w, b = _fold(sd, conv, bn)
    return _Conv(np.ascontiguousarray(w[:, :, 0, 0].T), b, 1, 1)  # (Cin, Cout) for x @ w


def _depthwise(sd, conv: str, bn: str, stride: int) -> _Conv:
    w, b = _fold(sd, conv, bn)
    k = w.shape[-1]
    return _Conv(np.ascontiguousarray(w[:, 0].transpose(1, 2, 0)), b, k, stride)  # (k, k, C)


class NumpyEfficientNetLite0:
    """Pooled 1280-d features of EfficientNet-Lite0 from a state dict of numpy arrays."""

    def __init__(self, state: dict[str, np.ndarray]):
        w, b = _fold(state, "_conv_stem", "_bn0")
        # im2col order (ky, kx, cin) -> (27, 32)
        self.stem = _Conv(np.ascontiguousarray(w.transpose(2, 3, 1, 0).reshape(-1, w.shape[0])), b, 3, 2)
        self.blocks: list[_Block] = []
        i = 0
        for kernel, repeats, cin, cout, expand, stride in LITE0_STAGES:
            for r in range(repeats):
                p = f"_blocks.{i}"
                s = stride if r == 0 else 1
                c_in = cin if r == 0 else cout
                self.blocks.append(
                    _Block(
                        expand=_pointwise(state, f"{p}._expand_conv", f"{p}._bn0") if expand != 1 else None,
                        depthwise=_depthwise(state, f"{p}._depthwise_conv", f"{p}._bn1", s),
                        project=_pointwise(state, f"{p}._project_conv", f"{p}._bn2"),
                        skip=s == 1 and c_in == cout,
                    )
                )
                assert self.blocks[-1].depthwise.kernel == kernel
                i += 1
        self.head = _pointwise(state, "_conv_head", "_bn1")
        assert self.head.weight.shape[1] == HEAD_CHANNELS
        self.fc_weight = np.ascontiguousarray(state["_fc.weight"].astype(np.float32).T)  # (1280, classes)
        self.fc_bias = state["_fc.bias"].astype(np.float32)

    @staticmethod
    def _relu6(x: np.ndarray) -> np.ndarray:
        return np.clip(x, 0.0, 6.0, out=x)

    @staticmethod
    def _apply_pointwise(x: np.ndarray, c: _Conv) -> np.ndarray:
        n, h, w, cin = x.shape
        y = x.reshape(-1, cin) @ c.weight
        y += c.bias
        return y.reshape(n, h, w, -1)

    @staticmethod
    def _apply_depthwise(x: np.ndarray, c: _Conv) -> np.ndarray:
        k, s = c.kernel, c.stride
        p = k // 2
        n, h, w, ch = x.shape
        ho, wo = (h + 2 * p - k) // s + 1, (w + 2 * p - k) // s + 1
        xp = np.pad(x, ((0, 0), (p, p), (p, p), (0, 0)))
        out = np.empty((n, ho, wo, ch), np.float32)
        out[...] = c.bias
        tmp = np.empty_like(out)
        for i in range(k):
            for j in range(k):
                np.multiply(
                    xp[:, i : i + s * (ho - 1) + 1 : s, j : j + s * (wo - 1) + 1 : s], c.weight[i, j], out=tmp
                )
                out += tmp
        return out

    def _apply_stem(self, x: np.ndarray) -> np.ndarray:
        c = self.stem
        n, h, w, _ = x.shape
        ho, wo = (h + 2 - 3) // 2 + 1, (w + 2 - 3) // 2 + 1
        xp = np.pad(x, ((0, 0), (1, 1), (1, 1), (0, 0)))
        cols = np.concatenate(
            [
                xp[:, i : i + 2 * (ho - 1) + 1 : 2, j : j + 2 * (wo - 1) + 1 : 2]
                for i in range(3)
                for j in range(3)
            ],
            axis=-1,
        )
        y = cols.reshape(-1, cols.shape[-1]) @ c.weight
        y += c.bias
        return y.reshape(n, ho, wo, -1)

    def features(self, x: np.ndarray) -> np.ndarray:
        """(N, H, W, 3) float32 normalised images (NHWC) -> (N, 1280) pooled features."""
        return self.feature_map(x).mean(axis=(1, 2))

    def feature_map(self, x: np.ndarray) -> np.ndarray:
        """(N, H, W, 3) float32 normalised images (NHWC) -> (N, H/32, W/32, 1280) head activations
        before pooling (what class activation maps are made of)."""
        h = self._relu6(self._apply_stem(np.asarray(x, np.float32)))
        for b in self.blocks:
            y = h
            if b.expand is not None:
                y = self._relu6(self._apply_pointwise(y, b.expand))
            y = self._relu6(self._apply_depthwise(y, b.depthwise))
            y = self._apply_pointwise(y, b.project)
            if b.skip:
                y += h
            h = y
        return self._relu6(self._apply_pointwise(h, self.head))

    def logits(self, x: np.ndarray) -> np.ndarray:
        """(N, H, W, 3) float32 normalised images -> (N, 1000) ImageNet logits."""
        return self.features(x) @ self.fc_weight + self.fc_bias


def load_numpy_model(path: str | Path) -> NumpyEfficientNetLite0:
    """The numpy network with the weights at ``path`` (a torch.save state dict)."""
    from ..errors import InputError
    from .state_dict import load_state_dict

    state = load_state_dict(path)
    try:
        return NumpyEfficientNetLite0(state)
    except KeyError as e:
        raise InputError(f"{path} is not an EfficientNet-Lite0 state dict (no {e.args[0]})") from None
