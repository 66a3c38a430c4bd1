"""Registers the ``clip`` embedder and the ``zooctl clip info`` command."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from zooctl.components import ComponentSpec
from zooctl.plugins import hookimpl

WEIGHTS_ENV = "ZOOCTL_CLIP_WEIGHTS"
ACT_ENV = "ZOOCTL_CLIP_ACT"


class ClipEmbedder:
    """CLIP image embeddings (N, embed_dim), unit length, of (N, H, W, 3) uint8 RGB crops."""

    name = "clip"
    input_kind = "rgb"

    def __init__(
        self, weights: str | Path | None = None, device: str = "cpu", act: str | None = None, batch: int = 32
    ):
        import torch

        from zooctl.errors import MissingDependencyError

        from .model import load_checkpoint

        weights = weights or os.environ.get(WEIGHTS_ENV)
        if not weights:
            raise MissingDependencyError(
                "the clip embedder needs a local CLIP checkpoint",
                hint=f"set {WEIGHTS_ENV}=/path/to/ViT-B-32.pt (nothing is downloaded)",
            )
        self.device = torch.device(device)
        act = act or os.environ.get(ACT_ENV, "quick_gelu")
        self.model = load_checkpoint(weights, act).to(self.device)
        self.dim = self.model.cfg.embed_dim
        from zooctl.embed.base import file_digest

        # Other weights of the same shape give other embeddings: views and queries record this.
        self.identity = f"clip/{file_digest(weights)}/{act}"
        self.batch = int(batch)
        self.weights = str(weights)

    def embed_batch(self, images: np.ndarray) -> np.ndarray:
        import torch

        from zooctl.embed.base import check_images, l2_normalize, resize_batch

        from .model import CLIP_MEAN, CLIP_STD

        images = check_images(images)
        size = self.model.cfg.image_size
        mean = torch.tensor(CLIP_MEAN).view(1, 3, 1, 1) * 255
        std = torch.tensor(CLIP_STD).view(1, 3, 1, 1) * 255
        out = []
        with torch.inference_mode():
            for i in range(0, len(images), self.batch):
                x = (
                    torch.from_numpy(np.ascontiguousarray(resize_batch(images[i : i + self.batch], size)))
                    .permute(0, 3, 1, 2)
                    .float()
                )
                out.append(self.model(((x - mean) / std).to(self.device)).float().cpu().numpy())
        return l2_normalize(np.concatenate(out))


def _clip(device: str = "cpu", **options: Any) -> ClipEmbedder:
    return ClipEmbedder(device=device, **options)


@hookimpl
def register_embedders(register):
    register(
        ComponentSpec(
            "embedder",
            "clip",
            _clip,
            f"CLIP/OpenCLIP ViT image embedding from a local checkpoint (${WEIGHTS_ENV})",
        )
    )


@hookimpl
def register_commands(cli):
    import typer

    group = typer.Typer(help="The CLIP embedder plugin.", no_args_is_help=True)

    @group.command("info")
    def info(
        weights: Path = typer.Option(None, "--weights", help=f"Checkpoint (default: ${WEIGHTS_ENV})."),
    ) -> None:
        """Load a CLIP checkpoint and print its image tower's architecture."""
        emb = ClipEmbedder(weights=weights)
        c = emb.model.cfg
        print(
            f"{emb.weights}: ViT width {c.width}, {c.layers} layers, {c.heads} heads, patch {c.patch}, {c.image_size} px, embedding {c.embed_dim}-d ({c.act})"
        )

    cli.add_typer(group, name="clip")
