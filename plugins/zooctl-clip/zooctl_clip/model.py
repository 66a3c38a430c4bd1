"""The CLIP vision transformer (Radford et al. 2021), parameter names as OpenAI CLIP / OpenCLIP.

Input (N, 3, R, R) normalised RGB (CLIP mean/std), R = patch * grid. Output (N, embed_dim): the
class token after ``ln_post``, projected by ``proj`` (the image embedding CLIP compares to text).
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

import torch
from torch import nn

CLIP_MEAN = (0.48145466, 0.4578275, 0.40821073)
CLIP_STD = (0.26862954, 0.26130258, 0.27577711)


class QuickGELU(nn.Module):
    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x * torch.sigmoid(1.702 * x)


@dataclass(frozen=True)
class VisionConfig:
    width: int
    layers: int
    heads: int
    patch: int
    grid: int
    embed_dim: int
    act: str = "quick_gelu"

    @property
    def image_size(self) -> int:
        return self.patch * self.grid


class ResidualAttentionBlock(nn.Module):
    def __init__(self, width: int, heads: int, act: str):
        super().__init__()
        self.attn = nn.MultiheadAttention(width, heads)
        self.ln_1 = nn.LayerNorm(width)
        self.mlp = nn.Sequential(
            OrderedDict(
                [
                    ("c_fc", nn.Linear(width, width * 4)),
                    ("gelu", QuickGELU() if act == "quick_gelu" else nn.GELU()),
                    ("c_proj", nn.Linear(width * 4, width)),
                ]
            )
        )
        self.ln_2 = nn.LayerNorm(width)

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # x (L, N, width)
        h = self.ln_1(x)
        x = x + self.attn(h, h, h, need_weights=False)[0]
        return x + self.mlp(self.ln_2(x))


class Transformer(nn.Module):
    def __init__(self, width: int, layers: int, heads: int, act: str):
        super().__init__()
        self.resblocks = nn.Sequential(*[ResidualAttentionBlock(width, heads, act) for _ in range(layers)])

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.resblocks(x)


class VisionTransformer(nn.Module):
    """CLIP's image tower. See the module docstring for shapes."""

    def __init__(self, cfg: VisionConfig):
        super().__init__()
        self.cfg = cfg
        w = cfg.width
        self.conv1 = nn.Conv2d(3, w, kernel_size=cfg.patch, stride=cfg.patch, bias=False)
        scale = w**-0.5
        self.class_embedding = nn.Parameter(scale * torch.randn(w))
        self.positional_embedding = nn.Parameter(scale * torch.randn(cfg.grid**2 + 1, w))
        self.ln_pre = nn.LayerNorm(w)
        self.transformer = Transformer(w, cfg.layers, cfg.heads, cfg.act)
        self.ln_post = nn.LayerNorm(w)
        self.proj = nn.Parameter(scale * torch.randn(w, cfg.embed_dim))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = self.conv1(x)  # (N, w, grid, grid)
        x = x.flatten(2).transpose(1, 2)  # (N, grid*grid, w)
        cls = self.class_embedding.to(x.dtype).expand(x.shape[0], 1, -1)
        x = torch.cat([cls, x], dim=1) + self.positional_embedding.to(x.dtype)
        x = self.ln_pre(x).transpose(0, 1)  # (L, N, w): nn.MultiheadAttention's default layout
        x = self.transformer(x).transpose(0, 1)
        return self.ln_post(x[:, 0]) @ self.proj


def _visual_state(raw: dict) -> dict[str, torch.Tensor]:
    """The ``visual.*`` tensors of a CLIP / OpenCLIP checkpoint, prefix removed."""
    state = raw.get("state_dict", raw) if isinstance(raw, dict) else raw
    out = {}
    for k, v in state.items():
        k = k[len("module.") :] if k.startswith("module.") else k
        if k.startswith("visual."):
            out[k[len("visual.") :]] = v
    return out


def config_from_state(state: dict[str, torch.Tensor], act: str = "quick_gelu") -> VisionConfig:
    """Read the architecture off the tensor shapes (raises KeyError/ValueError when it is not a ViT)."""
    conv = state["conv1.weight"]
    width, patch = int(conv.shape[0]), int(conv.shape[-1])
    tokens = int(state["positional_embedding"].shape[0])
    grid = math.isqrt(tokens - 1)
    if grid * grid != tokens - 1:
        raise ValueError(f"positional embedding of {tokens} tokens is not a square grid plus a class token")
    layers = len({k.split(".")[2] for k in state if k.startswith("transformer.resblocks.")})
    if width % 64:
        raise ValueError(f"width {width} is not a multiple of the head width 64")
    return VisionConfig(width, layers, width // 64, patch, grid, int(state["proj"].shape[1]), act)


def load_checkpoint(path: str | Path, act: str = "quick_gelu") -> VisionTransformer:
    """A `VisionTransformer` in eval mode from a local checkpoint (strict load). Errors are
    `zooctl.errors.InputError` naming what is wrong."""
    from zooctl.errors import InputError

    path = Path(path).expanduser()
    if not path.is_file():
        raise InputError(
            f"CLIP checkpoint {path} does not exist",
            hint="pass --weights PATH or set ZOOCTL_CLIP_WEIGHTS to a local .pt/.pth file",
        )
    try:
        raw = torch.load(path, map_location="cpu", weights_only=True)
    except Exception:
        # OpenAI's released .pt files are TorchScript archives: read as data, never run.
        from zooctl.embed.state_dict import load_state_dict

        try:
            raw = {k: torch.from_numpy(v.copy()) for k, v in load_state_dict(path).items()}
        except InputError as exc:
            raise InputError(
                f"{path} is not a plain PyTorch checkpoint: {exc.message}",
                hint="give a CLIP/OpenCLIP .pt or .pth file (weights only: a file that carries code is refused)",
            ) from None
    state = _visual_state(raw)
    if not state:
        raise InputError(
            f"{path} has no 'visual.*' tensors: not a CLIP checkpoint",
            hint="give the full CLIP model's state dict",
        )
    try:
        cfg = config_from_state(state, act)
    except (KeyError, ValueError) as exc:
        raise InputError(
            f"{path}: not a CLIP ViT image tower ({exc})",
            hint="only ViT CLIP models are supported (not ResNet ones)",
        ) from None
    model = VisionTransformer(cfg)
    try:
        model.load_state_dict(state, strict=True)
    except RuntimeError as exc:
        first = str(exc).splitlines()[0]
        raise InputError(
            f"{path}: the checkpoint does not match a CLIP ViT ({first})",
            hint="it may be damaged or of another architecture",
        ) from None
    return model.eval()
