"""The motion VAE and the ponymation prior (issue 8): tiny models, a few steps, CPU."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from zooctl.errors import InputError
from zooctl.motion.dataset import MotionDataset, sequences_from_asset
from zooctl.motion.losses import vae_losses
from zooctl.motion.model import MotionConfig, MotionVAE
from zooctl.motion.prior import PonymationPrior, motion_clip
from zooctl.motion.skeleton import Skeleton, SkeletonBatch
from zooctl.motion.train import TrainOptions, loss_curve_png
from zooctl.procedural import build_animal

TINY = dict(width=32, layers=1, heads=4, latent=16, length=8)


@pytest.fixture(autouse=True)
def _one_thread():
    n = torch.get_num_threads()
    torch.set_num_threads(1)  # 2 shared cores: no oversubscription from tiny ops
    yield
    torch.set_num_threads(n)


@pytest.fixture(scope="module")
def animals():
    return build_animal("quadruped"), build_animal("fish")


def _randomise_output(model: MotionVAE) -> None:
    """The output layer starts at zero (rest pose); give it weights so z matters."""
    g = torch.Generator().manual_seed(0)
    with torch.no_grad():
        model.rot_out.weight.copy_(torch.randn(model.rot_out.weight.shape, generator=g) * 0.3)


def test_untrained_model_outputs_the_rest_pose(animals):
    quad, fish = animals
    model = MotionVAE(MotionConfig(**TINY))
    sk = SkeletonBatch([Skeleton.from_asset(quad), Skeleton.from_asset(fish)])
    out = model.decode(torch.randn(2, 16), sk)
    assert out.shape == (2, 8, quad.num_joints, 6)
    assert torch.allclose(out, torch.tensor([1.0, 0, 0, 0, 1, 0]).expand_as(out))


def test_padding_does_not_change_a_skeletons_result(animals):
    """A fish alone and a fish padded next to a 23-joint quadruped encode and decode the same."""
    quad, fish = animals
    torch.manual_seed(0)
    model = MotionVAE(MotionConfig(**TINY)).eval()
    _randomise_output(model)
    ds = MotionDataset(sequences_from_asset(fish) + sequences_from_asset(quad), length=8, speeds=())
    fish_ids = np.nonzero(ds.skel_ids == 0)[0][:1]
    quad_ids = np.nonzero(ds.skel_ids == 1)[0][:1]
    alone = ds.batch(fish_ids)
    mixed = ds.batch(np.concatenate([fish_ids, quad_ids]))
    with torch.no_grad():
        mu_a, _ = model.encode(alone.rot6d, alone.skeletons)
        mu_m, _ = model.encode(mixed.rot6d, mixed.skeletons)
        assert torch.allclose(mu_a[0], mu_m[0], atol=1e-5)
        z = torch.randn(1, 16)
        dec_a = model.decode(z, alone.skeletons)
        dec_m = model.decode(z.expand(2, -1), mixed.skeletons)
    J = fish.num_joints
    assert torch.allclose(dec_a[0], dec_m[0, :, :J], atol=1e-5)


def test_a_few_steps_of_training_reduce_the_loss(animals):
    quad, fish = animals
    torch.manual_seed(0)  # the initial weights: the test ran with whatever RNG state came before it
    prior = PonymationPrior(MotionConfig(**TINY))
    data = prior.dataset(sequences_from_asset(quad)[:1] + sequences_from_asset(fish)[:1], speeds=())
    batch = data.batch(np.arange(len(data)))
    with torch.no_grad():
        pred, mu, lv = prior.model(batch.rot6d, batch.skeletons, sample=False)
        before = vae_losses(pred, batch.rotmat, mu, lv, batch.skeletons, prior.cfg, 1.0, batch.joint_motion)
    hist = prior.fit(data, TrainOptions(epochs=30, batch_size=16, lr=3e-3, warmup_steps=5))
    with torch.no_grad():
        pred, mu, lv = prior.model(batch.rot6d, batch.skeletons, sample=False)
        after = vae_losses(pred, batch.rotmat, mu, lv, batch.skeletons, prior.cfg, 1.0, batch.joint_motion)
    assert hist.steps >= 25 and len(hist.total) == hist.steps
    # A 32-wide one-layer model in 30 steps learns the mean pose, not yet the motion: the losses drop
    # (a broken gradient path leaves the losses where they start); the velocity terms (about 1 each
    # for a still output) make most of the total and barely move yet.
    assert float(after["total"]) < 0.995 * float(before["total"])
    assert float(after["rotation"]) < float(before["rotation"])
    assert float(after["joints"]) < float(before["joints"])
    assert float(prior.model.rot_gain) > 1.0  # input standardised from the training data
    png = loss_curve_png(hist)
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert prior.training["steps"] == hist.steps and set(prior.training["skeletons"]) == {"quadruped", "fish"}


def test_sampling_is_seeded_valid_and_any_length(animals):
    quad, _ = animals
    torch.manual_seed(1)  # before the model: its initial weights too
    prior = PonymationPrior(MotionConfig(**TINY))
    _randomise_output(prior.model)
    a = prior.sample(quad, n=3, frames=30, seed=7, transition_steps=3)
    assert a.shape == (3, 30, quad.num_joints, 4)
    assert np.allclose(np.linalg.norm(a, axis=-1), 1.0, atol=1e-6)
    assert np.allclose(a, prior.sample(quad, n=3, frames=30, seed=7, transition_steps=3))
    assert not np.allclose(a, prior.sample(quad, n=3, frames=30, seed=8, transition_steps=3))
    assert not np.allclose(a[0], a[1])
    assert prior.sample(quad, n=1, frames=5, seed=0).shape == (1, 5, quad.num_joints, 4)
    clip = motion_clip(quad, a[0], 30.0, "s0")
    quad2 = quad.__class__(**{**quad.__dict__, "clips": {"s0": clip}})
    quad2.validate()
    with pytest.raises(InputError):
        prior.sample(quad, n=0, frames=10)


def test_transition_latents_close_the_gap_between_segments(animals):
    """Optimised transition latents start where one segment ends and end where the next starts
    (Ponymation appendix A): the boundary error shrinks below a random latent's, and after the
    residual correction the segments join exactly, so chained samples have no jumps."""
    from zooctl.motion.prior import transition_error

    quad, _ = animals
    torch.manual_seed(2)  # before the model: its initial weights too
    prior = PonymationPrior(MotionConfig(**TINY))
    _randomise_output(prior.model)
    L, n = prior.cfg.length, 3
    g = torch.Generator().manual_seed(0)
    with torch.no_grad():
        content = prior.model.decode_frames(torch.randn(n * 2, 16, generator=g), L).reshape(n, 2, L, -1)
    z0 = torch.randn(n, 16, generator=g)
    prev, nxt = prior._ends(content)
    skb = prior._skeletons(Skeleton.from_asset(quad), n)

    def err(z: torch.Tensor) -> float:
        with torch.no_grad():
            return float(transition_error(prior.model.decode_frames(z, L), prev, nxt).mean())

    z1 = prior._optimise_transitions(z0, content, steps=60, sk=skb)
    assert err(z1) < 0.85 * err(z0)  # 60 steps: 0.48-0.78 of it over ten initial models
    t = prior._transition_frames(z1, content, skb)[:, 0]
    assert torch.allclose(t[:, 0], prev[:, -1], atol=1e-5) and torch.allclose(t[:, -1], nxt[:, 0], atol=1e-5)
    # A chained sample's largest frame-to-frame step is no larger than within its content segments.
    from zooctl.motion import metrics as M

    sk = Skeleton.from_asset(quad)
    p = M.joint_positions(prior.sample_delta(sk, 2, 3 * L, seed=3, transition_steps=60), sk)
    steps = np.linalg.norm(np.diff(p, axis=1), axis=-1).max(-1)  # (2, T-1)
    seams = [L - 1, 2 * L - 3]  # c_0[-1] -> t_0[1] and t_0[-2] -> c_1[0]
    inside = np.delete(steps, seams, axis=1)
    assert steps[:, seams].max() <= 2.0 * inside.max() + 1e-6


def test_save_and_load_give_the_same_samples(tmp_path, animals):
    quad, _ = animals
    prior = PonymationPrior(MotionConfig(**TINY))
    _randomise_output(prior.model)
    prior.save(tmp_path / "p", "p")
    again = PonymationPrior.load(tmp_path / "p")
    assert again.cfg == prior.cfg
    assert np.allclose(
        prior.sample(quad, 2, 12, seed=1, transition_steps=2),
        again.sample(quad, 2, 12, seed=1, transition_steps=2),
    )


def test_bad_configs_are_clear_errors():
    with pytest.raises(InputError, match="divisible"):
        MotionConfig(width=30, heads=4)
    with pytest.raises(InputError, match="length"):
        MotionConfig(length=1)


def test_temperature_scales_the_spread_of_samples(animals):
    quad, _ = animals
    torch.manual_seed(4)  # before the model: its initial weights too
    prior = PonymationPrior(MotionConfig(**TINY))
    _randomise_output(prior.model)
    sk = Skeleton.from_asset(quad)
    still = prior.sample_delta(sk, 3, 20, seed=0, temperature=0.0, transition_steps=2)
    assert np.allclose(still[0], still[1], atol=1e-6)  # z = 0 for every sample
    from zooctl.motion import metrics as M

    spread = [
        M.diversity(M.joint_positions(prior.sample_delta(sk, 6, 8, seed=0, temperature=t), sk))
        for t in (0.5, 2.0)
    ]
    assert spread[0] < spread[1]
    with pytest.raises(InputError, match="temperature"):
        prior.sample_delta(sk, 1, 8, temperature=-1.0)


def test_calibrated_temperature_matches_the_training_diversity(animals):
    from zooctl.motion.calibrate import calibrate_temperature

    quad, _ = animals
    prior = PonymationPrior(MotionConfig(**TINY, diverse=False))  # calibrated: independent draws
    torch.manual_seed(4)
    _randomise_output(prior.model)
    data = prior.dataset(sequences_from_asset(quad), speeds=())  # one skeleton: its ratio decides
    cal = calibrate_temperature(prior, data, grid=(0.25, 1.0, 4.0), samples=6, windows=12)
    real, div = cal["real_diversity"], {float(t): d for t, d in cal["diversity"].items()}
    assert real > 0 and div[0.25] < div[1.0] < div[4.0]  # wider latent, more varied motion
    assert cal["temperature"] == min(div, key=lambda t: abs(np.log(div[t] / real)))
    # Training stores the calibrated temperature; sampling uses it unless told otherwise.
    prior.fit(data, TrainOptions(epochs=1, batch_size=16, lr=3e-3, warmup_steps=1))
    t = prior.training["sample_temperature"]
    assert t == prior.training["calibration"]["temperature"] == prior.sample_temperature
    sk = Skeleton.from_asset(quad)
    a = prior.sample_delta(sk, 3, 8, seed=2, transition_steps=1)
    assert np.allclose(a, prior.sample_delta(sk, 3, 8, seed=2, transition_steps=1, temperature=t))
    # Drawing a call's windows together (the default), the spread comes from the windows: each is
    # sampled from its own posterior (temperature 1), nothing is calibrated.
    diverse = PonymationPrior(MotionConfig(**TINY))
    diverse.fit(data, TrainOptions(epochs=1, batch_size=16, lr=3e-3, warmup_steps=1))
    assert diverse.sample_temperature == diverse.training["sample_temperature"] == 1.0
    assert "calibration" not in diverse.training
    diverse.training["sample_temperature"] = 8.0  # what an older prior stored for independent draws
    assert diverse.sample_temperature == 1.0


def test_relative_rotation_loss_weighs_each_joint_by_its_own_motion(animals):
    """A still output (each window's mean pose) scores about 1 whatever the joints' amplitudes, and
    a small-moving joint's error counts as much as a large-moving one's of the same relative size."""
    from zooctl.motion.losses import relative_rotation_loss

    quad, _ = animals
    ds = MotionDataset(sequences_from_asset(quad), length=8, speeds=())
    J = quad.num_joints
    assert ds.joint_motion.shape == (1, J) and (ds.joint_motion >= 0).all() and ds.joint_motion.max() > 0
    b = ds.batch(np.arange(len(ds)))
    assert b.joint_motion.shape == (len(ds), J)
    still = b.rotmat.mean(1, keepdim=True).expand_as(b.rotmat)
    moving = b.joint_motion[0] > 0.1 * b.joint_motion[0].mean()
    loss = relative_rotation_loss(still, b.rotmat, b.skeletons.mask, b.joint_motion)
    assert 0.5 < float(loss) <= 1.0
    # Halving the error of every joint halves the loss; a plain MSE would be dominated by the
    # joints that move most, this one is not: the two halves of the moving joints count alike.
    half = b.rotmat + 0.5**0.5 * (still - b.rotmat)
    assert float(relative_rotation_loss(half, b.rotmat, b.skeletons.mask, b.joint_motion)) == pytest.approx(
        0.5 * float(loss), rel=1e-4
    )
    order = torch.argsort(b.joint_motion[0] * moving)
    small, large = order[-int(moving.sum()) :][:3], order[-3:]
    per = ((still - b.rotmat) ** 2).sum((-1, -2)).mean((0, 1)) / (
        b.joint_motion[0] + 0.1 * b.joint_motion[0].mean()
    )
    assert float(per[small].mean()) == pytest.approx(float(per[large].mean()), rel=0.5)
    cfg = MotionConfig(**TINY, rot_loss="relative")
    pred6d = torch.cat([b.rotmat[..., 0], b.rotmat[..., 1]], -1)  # exact prediction: no rotation error
    mu = torch.zeros(len(ds), 16)
    out = vae_losses(pred6d, b.rotmat, mu, mu, b.skeletons, cfg, 0.0, b.joint_motion)
    assert float(out["rotation"]) < 1e-8


def test_max_steps_stops_training_after_that_many_steps(animals):
    quad, _ = animals
    prior = PonymationPrior(MotionConfig(**TINY))
    data = prior.dataset(sequences_from_asset(quad)[:1], speeds=())
    hist = prior.fit(data, TrainOptions(epochs=50, batch_size=4, lr=3e-3, warmup_steps=1, max_steps=7))
    assert hist.steps == 7 and hist.stopped_early and prior.training["steps"] == 7
