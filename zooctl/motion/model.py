"""`MotionVAE`: Ponymation's spatio-temporal transformer VAE (section 3.3, appendix B), for
variable skeletons through padded bone tokens.

Shapes: B windows, T frames, J (padded) joints, W width, Z latent size.

- Spatial encoder E_s: per frame, J bone tokens (6D rotation + static bone features: rest
  position, offset from parent, leaf flag, index/depth/parent encodings) with a learnable token
  prepended; padded bones are masked. The learnable token's output is the frame's pose feature.
- Temporal encoder E_t: [mu token, sigma token, T pose features + time encoding] -> mu, log var.
- Temporal decoder D_t: T timestamp queries attend to z -> T frame features.
- Spatial decoder D_s: J bone queries (static features) attend to the frame feature -> 6D per bone,
  added to the identity so an untrained model outputs the rest pose.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any

import torch
from torch import nn

from ..errors import InputError
from .skeleton import STATIC_FEATURES, SkeletonBatch

IDENTITY_6D = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0)


@dataclass
class MotionConfig:
    """Model and training hyper-parameters; stored as the prior's ``config.json`` ``model``."""

    width: int = 256
    layers: int = 4
    heads: int = 4
    ff_mult: int = 2
    latent: int = 256
    length: int = 10
    fps: float = 30.0
    dropout: float = 0.0  # dropout costs a third of a CPU step and the VAE noise regularises already
    kl_weight: float = 1e-3
    free_bits: float = 0.5  # nats per latent dimension the KL leaves free (see `losses`)
    rot_weight: float = 1.0
    # "relative": each joint's rotation error over its own motion in the data
    # (`losses.relative_rotation_loss`), so leaf bones and little-moving joints count; "mse": one
    # MSE over all bones, which the joints with big pose offsets dominate (BENCHMARKS.md).
    rot_loss: str = "relative"
    # Positions are in skeleton diagonals, so their errors are small (MSE ~1e-3): at 10 the KL
    # outweighed them and the decoder learned to ignore z (see `losses`).
    joint_weight: float = 100.0
    # Relative joint-velocity error (`losses.velocity_loss`): pose errors alone let a decoder that
    # outputs each window's mean pose score well, and its samples stand still.
    velocity_weight: float = 1.0
    # The same relative error on the bones' *rotation matrices*: joint positions do not see a leaf
    # bone's rotation nor a twist, so with positions alone the most-rotating bones (ears, tail tips,
    # fins) were reconstructed with a tenth of their motion.
    rot_velocity_weight: float = 1.0
    # z also added to the decoder's timestamp queries, so it shapes how frames attend to each other.
    z_queries: bool = False
    # Where samples draw z: "posterior", a Gaussian per skeleton fitted to its training windows'
    # posterior means (`latents`); "mixture", around a random training window's posterior mean
    # (the aggregate posterior); or "normal", N(0, I).
    sampler: str = "mixture"
    # Mixture sampling: this share of the windows comes from up to `donors` other trained
    # skeletons whose latents overlap this one's (`latents.LatentGaussians.donors_of`): the same
    # body plan's actions on this animal. 0 draws from the skeleton's own windows only.
    donors: int = 3
    donor_share: float = 0.5
    # Mixture sampling: the windows of one call's samples are drawn together and spread over the
    # skeleton's latents (`latents.diverse_indices`) instead of independently, so a call's samples
    # are different actions. Sampling only; priors saved without it get it.
    diverse: bool = True
    # "ponymation": per-frame spatial and temporal transformers (the paper's); "trajectory": one
    # token per bone carrying its whole window (`TrajectoryVAE`), T times fewer tokens.
    arch: str = "ponymation"
    # Trajectory model: z enters the decoder as this many memory tokens. With one, softmax over a
    # single key makes cross-attention add the same vector to every bone, and bones differ only
    # through the feed-forward layers; with 8 each bone attends to its own mix (on the two-motion
    # toy of tests/test_motion_collapse.py: amplitude / speed ratio 1.0 / 0.9 against 1.3 / 1.6).
    z_tokens: int = 8
    # Train on every clip's left-right mirror too (`zooctl.motion.mirror`; skeletons with named
    # left/right joints). Off: it was not better in a 20-minute A/B (BENCHMARKS.md).
    mirror: bool = False

    def __post_init__(self) -> None:
        if self.width < 8 or self.width % self.heads:
            raise InputError(
                f"width must be at least 8 and divisible by heads ({self.heads}), got {self.width}"
            )
        if self.free_bits < 0 or self.kl_weight < 0:
            raise InputError("kl_weight and free_bits must be >= 0")
        if self.arch not in ("ponymation", "trajectory"):
            raise InputError(f"arch must be 'ponymation' or 'trajectory', got {self.arch!r}")
        if self.sampler not in ("posterior", "mixture", "normal"):
            raise InputError(f"sampler must be 'posterior', 'mixture' or 'normal', got {self.sampler!r}")
        if self.rot_loss not in ("mse", "relative"):
            raise InputError(f"rot_loss must be 'mse' or 'relative', got {self.rot_loss!r}")
        if self.donors < 0 or not 0.0 <= self.donor_share <= 1.0:
            raise InputError(
                f"donors must be >= 0 and donor_share in [0, 1], got {self.donors}, {self.donor_share}"
            )
        if self.z_tokens < 1:
            raise InputError(f"z_tokens must be >= 1, got {self.z_tokens}")
        if self.layers < 1 or self.latent < 1 or self.length < 2 or not self.fps > 0:
            raise InputError("layers and latent must be >= 1, length >= 2 frames and fps > 0")

    def to_json(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> MotionConfig:
        known = {f.name for f in fields(cls)}
        d = {"z_tokens": 1, **d}  # priors saved before z_tokens existed decode from one token
        return cls(**{k: v for k, v in d.items() if k in known})


def time_encoding(t: torch.Tensor, dim: int) -> torch.Tensor:
    """Sinusoidal encoding of (possibly fractional) frame indices. t (...,) -> (..., dim)."""
    half = dim // 2
    freq = torch.exp(-math.log(1000.0) * torch.arange(half, device=t.device, dtype=torch.float32) / half)
    a = t.float()[..., None] * freq
    return torch.cat([torch.sin(a), torch.cos(a)], -1)


def _encoder(cfg: MotionConfig) -> nn.TransformerEncoder:
    layer = nn.TransformerEncoderLayer(
        cfg.width, cfg.heads, cfg.width * cfg.ff_mult, cfg.dropout, batch_first=True, norm_first=True
    )
    return nn.TransformerEncoder(layer, cfg.layers, enable_nested_tensor=False)


def _decoder(cfg: MotionConfig) -> nn.TransformerDecoder:
    layer = nn.TransformerDecoderLayer(
        cfg.width, cfg.heads, cfg.width * cfg.ff_mult, cfg.dropout, batch_first=True, norm_first=True
    )
    return nn.TransformerDecoder(layer, cfg.layers)


def _memory_value(layer: nn.TransformerDecoderLayer, memory: torch.Tensor) -> torch.Tensor:
    """Cross-attention of any query to a *single* memory token: softmax over one key is 1, so the
    output is ``out_proj(v_proj(memory))`` whatever the query. memory (N, W) -> (N, W)."""
    att = layer.multihead_attn
    W = memory.shape[-1]
    v = nn.functional.linear(memory, att.in_proj_weight[2 * W :], att.in_proj_bias[2 * W :])
    return att.out_proj(v)


def padding_attn_mask(pad: torch.Tensor, heads: int) -> torch.Tensor:
    """pad (B, S) True where a token is padding -> bool attention mask (B * heads, S, S) that
    hides those keys: what ``key_padding_mask=pad`` does, without torch's key-padding shape
    check, whose first call imports sympy (a noticeable part of every ``zooctl animate``;
    BENCHMARKS.md, Motion prior)."""
    B, S = pad.shape
    return pad[:, None, None, :].expand(B, heads, S, S).reshape(B * heads, S, S)


def decode_single_memory(
    decoder: nn.TransformerDecoder,
    queries: torch.Tensor,
    memory: torch.Tensor,
    pad: torch.Tensor | None = None,
) -> torch.Tensor:
    """``decoder(tgt, memory[:, None])`` for pre-norm layers and one memory token per group of
    queries, exactly, at a fraction of the cost.

    queries (G, S, W) are shared by the N = G * R sequences of a group (R: e.g. the frames of a
    window); memory (G, R, W), one token per sequence; pad (G, S) True where a query is padding.
    Returns (G, R, S, W). The first self-attention runs once per group (its input does not depend
    on the memory yet), cross-attention is one matrix product per sequence instead of per token.
    """
    G, S, W = queries.shape
    R = memory.shape[1]
    x = queries
    heads = decoder.layers[0].self_attn.num_heads
    # the group's mask (G * heads, S, S), and the same repeated for its R sequences (later layers)
    m = None if pad is None else padding_attn_mask(pad, heads)
    p = None if m is None else m.reshape(G, 1, heads, S, S).expand(G, R, heads, S, S).reshape(-1, S, S)
    for i, layer in enumerate(decoder.layers):
        if i == 0:
            x = x + layer._sa_block(layer.norm1(x), m, None)  # (G, S, W)
            x = (x[:, None] + layer.dropout2(_memory_value(layer, memory))[:, :, None]).reshape(G * R, S, W)
        else:
            x = x + layer._sa_block(layer.norm1(x), p, None)
            x = x + layer.dropout2(_memory_value(layer, memory.reshape(G * R, W)))[:, None]
        x = x + layer._ff_block(layer.norm3(x))
    if decoder.norm is not None:
        x = decoder.norm(x)
    return x.reshape(G, R, S, W)


class MotionVAE(nn.Module):
    def __init__(self, cfg: MotionConfig):
        super().__init__()
        self.cfg = cfg
        W = cfg.width
        self.rot_in = nn.Linear(6, W)
        self.bone_in = nn.Linear(STATIC_FEATURES, W)
        self.frame_token = nn.Parameter(torch.randn(W) * 0.02)
        self.spatial_encoder = _encoder(cfg)
        self.mu_token = nn.Parameter(torch.randn(W) * 0.02)
        self.sigma_token = nn.Parameter(torch.randn(W) * 0.02)
        self.time_in = nn.Linear(W, W)
        self.temporal_encoder = _encoder(cfg)
        self.to_mu = nn.Linear(W, cfg.latent)
        self.to_logvar = nn.Linear(W, cfg.latent)
        # Start with a narrow posterior (sigma ~0.14): with sigma = 1 the encoder's first small
        # means drown in the sampling noise and the decoder learns to ignore z before it can use it.
        nn.init.constant_(self.to_logvar.bias, -4.0)
        self.z_in = nn.Linear(cfg.latent, W)
        self.temporal_decoder = _decoder(cfg)
        self.bone_query = nn.Linear(STATIC_FEATURES, W)
        self.spatial_decoder = _decoder(cfg)
        self.norm_out = nn.LayerNorm(W)
        self.rot_out = nn.Linear(W, 6)
        nn.init.zeros_(self.rot_out.weight)
        nn.init.zeros_(self.rot_out.bias)
        self.register_buffer("identity6d", torch.tensor(IDENTITY_6D), persistent=False)
        # Bones move ~0.1 away from identity in 6D while the static features are ~1: without
        # rescaling, the pose signal drowns and the encoder learns nothing beyond the mean pose.
        # `fit` sets this to 1 / std of the training deviations; it is saved with the weights.
        self.register_buffer("rot_gain", torch.tensor(1.0))

    # -- encoder --------------------------------------------------------------------------
    def encode(self, rot6d: torch.Tensor, sk: SkeletonBatch) -> tuple[torch.Tensor, torch.Tensor]:
        """rot6d (B, T, J, 6) -> mu, logvar (B, Z)."""
        B, T, J, _ = rot6d.shape
        tokens = (
            self.rot_in((rot6d - self.identity6d) * self.rot_gain) + self.bone_in(sk.static)[:, None]
        )  # (B, T, J, W)
        tokens = torch.cat([self.frame_token.expand(B, T, 1, -1), tokens], 2).reshape(B * T, J + 1, -1)
        pad = torch.cat([sk.mask.new_zeros(B, 1), ~sk.mask], 1)  # True: ignore
        pad = pad[:, None].expand(B, T, J + 1).reshape(B * T, J + 1)
        pose = self.spatial_encoder(tokens, mask=padding_attn_mask(pad, self.cfg.heads))[:, 0].reshape(
            B, T, -1
        )
        frames = pose + self.time_in(time_encoding(torch.arange(T, device=rot6d.device), self.cfg.width))
        seq = torch.cat([self.mu_token.expand(B, 1, -1), self.sigma_token.expand(B, 1, -1), frames], 1)
        out = self.temporal_encoder(seq)
        return self.to_mu(out[:, 0]), self.to_logvar(out[:, 1]).clamp(-12.0, 6.0)

    # -- decoder --------------------------------------------------------------------------
    def decode_frames(self, z: torch.Tensor, T: int) -> torch.Tensor:
        """z (B, Z) -> frame features (B, T, W) at timestamps 0..T-1."""
        queries = self.time_in(time_encoding(torch.arange(T, device=z.device), self.cfg.width))
        m = self.z_in(z)
        if self.cfg.z_queries:
            # Cross-attention to one token only adds a z-dependent constant to every frame; the
            # frames' motion then barely depends on z. Here z also enters the self-attention.
            return decode_single_memory(self.temporal_decoder, queries[None] + m[:, None], m[:, None])[:, 0]
        # All B windows share the timestamp queries: one group of B sequences.
        return decode_single_memory(self.temporal_decoder, queries[None], m[None])[0]

    def decode_bones(self, frames: torch.Tensor, sk: SkeletonBatch) -> torch.Tensor:
        """frame features (B, T, W) -> 6D rotations (B, T, J, 6) relative to rest."""
        # Each window's T frames share its skeleton's bone queries: one group of T sequences.
        out = decode_single_memory(self.spatial_decoder, self.bone_query(sk.static), frames, ~sk.mask)
        return self.rot_out(self.norm_out(out)) + self.identity6d  # (B, T, J, 6)

    def decode(self, z: torch.Tensor, sk: SkeletonBatch, T: int | None = None) -> torch.Tensor:
        """z (B, Z) -> 6D rotations (B, T, J, 6)."""
        return self.decode_bones(self.decode_frames(z, T or self.cfg.length), sk)

    def forward(self, rot6d: torch.Tensor, sk: SkeletonBatch, sample: bool = True):
        """Reconstruct: returns (6D rotations (B, T, J, 6), mu, logvar)."""
        mu, logvar = self.encode(rot6d, sk)
        z = mu + torch.randn_like(mu) * torch.exp(0.5 * logvar) if sample else mu
        return self.decode(z, sk, rot6d.shape[1]), mu, logvar

    # -- what chained sampling uses (`prior`) -----------------------------------------------
    def frame_features(self, z: torch.Tensor, sk: SkeletonBatch) -> torch.Tensor:
        """z (B, Z) -> per-frame features (B, L, D) that `features_to_rot6d` turns into poses."""
        return self.decode_frames(z, self.cfg.length)

    def features_to_rot6d(self, feats: torch.Tensor, sk: SkeletonBatch) -> torch.Tensor:
        """(B, T, D) -> 6D rotations (B, T, J, 6)."""
        return self.decode_bones(feats, sk)


class TrajectoryVAE(nn.Module):
    """The VAE with one token per bone holding its whole window: the encoder reads each bone's
    T x 6 rotations (plus its static features), the decoder's bone queries attend to z and emit
    each bone's T x 6 trajectory through a linear head. Shapes as in `MotionVAE`; windows are
    ``cfg.length`` frames. Same losses, sampling and chaining; T times fewer tokens than the
    per-frame model, and motion is an output of the head rather than something the decoder must
    build frame by frame from timestamp queries."""

    def __init__(self, cfg: MotionConfig):
        super().__init__()
        self.cfg = cfg
        W, L = cfg.width, cfg.length
        self.traj_in = nn.Linear(6 * L, W)
        self.bone_in = nn.Linear(STATIC_FEATURES, W)
        self.mu_token = nn.Parameter(torch.randn(W) * 0.02)
        self.sigma_token = nn.Parameter(torch.randn(W) * 0.02)
        self.encoder = _encoder(cfg)
        self.to_mu = nn.Linear(W, cfg.latent)
        self.to_logvar = nn.Linear(W, cfg.latent)
        nn.init.constant_(self.to_logvar.bias, -4.0)  # see `MotionVAE`
        self.z_in = nn.Linear(cfg.latent, W * cfg.z_tokens)
        if cfg.z_tokens > 1:
            self.z_pos = nn.Parameter(torch.randn(cfg.z_tokens, W) * 0.02)
        self.bone_query = nn.Linear(STATIC_FEATURES, W)
        self.decoder = _decoder(cfg)
        self.norm_out = nn.LayerNorm(W)
        self.traj_out = nn.Linear(W, 6 * L)
        nn.init.zeros_(self.traj_out.weight)
        nn.init.zeros_(self.traj_out.bias)
        self.register_buffer("identity6d", torch.tensor(IDENTITY_6D), persistent=False)
        self.register_buffer("rot_gain", torch.tensor(1.0))  # set by `train_vae`, as in `MotionVAE`

    def _check(self, T: int) -> None:
        if T != self.cfg.length:
            raise InputError(f"this model reads and writes windows of {self.cfg.length} frames, got {T}")

    def encode(self, rot6d: torch.Tensor, sk: SkeletonBatch) -> tuple[torch.Tensor, torch.Tensor]:
        """rot6d (B, T, J, 6) -> mu, logvar (B, Z)."""
        B, T, J, _ = rot6d.shape
        self._check(T)
        traj = ((rot6d - self.identity6d) * self.rot_gain).permute(0, 2, 1, 3).reshape(B, J, T * 6)
        tokens = self.traj_in(traj) + self.bone_in(sk.static)  # (B, J, W)
        seq = torch.cat([self.mu_token.expand(B, 1, -1), self.sigma_token.expand(B, 1, -1), tokens], 1)
        pad = torch.cat([sk.mask.new_zeros(B, 2), ~sk.mask], 1)
        out = self.encoder(seq, mask=padding_attn_mask(pad, self.cfg.heads))
        return self.to_mu(out[:, 0]), self.to_logvar(out[:, 1]).clamp(-12.0, 6.0)

    def decode(self, z: torch.Tensor, sk: SkeletonBatch, T: int | None = None) -> torch.Tensor:
        """z (B, Z) -> 6D rotations (B, T, J, 6)."""
        L = self.cfg.length
        self._check(T or L)
        B, J = z.shape[0], sk.mask.shape[1]
        q, M = self.bone_query(sk.static), self.cfg.z_tokens
        if M == 1:
            h = decode_single_memory(self.decoder, q, self.z_in(z)[:, None], ~sk.mask)[:, 0]
        else:  # each bone query attends to its own mix of the z tokens
            memory = self.z_in(z).reshape(B, M, -1) + self.z_pos
            h = self.decoder(q, memory, tgt_mask=padding_attn_mask(~sk.mask, self.cfg.heads))
        out = self.traj_out(self.norm_out(h)).reshape(B, J, L, 6).permute(0, 2, 1, 3)
        return out + self.identity6d

    def forward(self, rot6d: torch.Tensor, sk: SkeletonBatch, sample: bool = True):
        mu, logvar = self.encode(rot6d, sk)
        z = mu + torch.randn_like(mu) * torch.exp(0.5 * logvar) if sample else mu
        return self.decode(z, sk), mu, logvar

    def frame_features(self, z: torch.Tensor, sk: SkeletonBatch) -> torch.Tensor:
        """The decoded poses themselves, flattened: (B, L, J * 6)."""
        r = self.decode(z, sk)
        return r.reshape(*r.shape[:2], -1)

    def features_to_rot6d(self, feats: torch.Tensor, sk: SkeletonBatch) -> torch.Tensor:
        return feats.reshape(*feats.shape[:2], -1, 6)


def build_model(cfg: MotionConfig) -> nn.Module:
    return TrajectoryVAE(cfg) if cfg.arch == "trajectory" else MotionVAE(cfg)
