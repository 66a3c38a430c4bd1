"""The procedural starter bank: every body plan, closed meshes, smooth skinning, looping clips,
determinism, and `zooctl bank seed` into a real store."""

from __future__ import annotations

import numpy as np
import pytest
from cli_helpers import zooctl

from zooctl.errors import InputError
from zooctl.procedural import PLANS, VARIANTS, BodyParams, build_animal, seed_bank, starter_assets

REQUIRED_PLANS = {"quadruped", "biped", "bird", "fish", "snake", "insect", "spider", "dinosaur", "crab"}
CLIPS = {
    "quadruped": {"walk", "trot", "idle"},
    "biped": {"walk", "idle"},
    "bird": {"flap", "walk", "idle"},
    "fish": {"swim", "idle"},
    "snake": {"slither", "idle"},
    "insect": {"walk", "idle"},
    "spider": {"walk", "idle"},
    "dinosaur": {"walk", "idle", "roar"},
    "crab": {"walk", "idle", "snap"},
}
LEGS = {"quadruped": 4, "biped": 2, "bird": 2, "insect": 6, "spider": 8, "dinosaur": 2, "crab": 8}


@pytest.fixture(scope="module")
def bank_assets():
    return starter_assets(0)


def components(faces: np.ndarray, n: int) -> np.ndarray:
    """Connected-component label of every vertex."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    _, labels = connected_components(
        coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)), directed=False
    )
    return labels


def test_every_body_plan_with_variants(bank_assets):
    assert REQUIRED_PLANS <= set(PLANS)
    names = [a.name for a in bank_assets]
    assert len(names) == len(set(names)) == sum(len(v) for v in VARIANTS.values())
    for plan in REQUIRED_PLANS:
        variants = [a for a in bank_assets if a.meta["body_plan"] == plan]
        assert len(variants) >= 2, plan
        props = {tuple(sorted(a.meta["proportions"].items())) for a in variants}
        assert len(props) == len(variants), f"{plan} variants share proportions"


@pytest.mark.parametrize("index", range(19))
def test_starter_animal_is_a_sound_rig(bank_assets, index):
    a = bank_assets[index]
    plan = a.meta["body_plan"]
    assert 2000 <= a.num_vertices <= 6000, a.num_vertices  # a few thousand vertices
    # Closed, outward-oriented parts: every directed edge has its reverse exactly once.
    f = a.faces.astype(np.int64)
    fwd = f.reshape(-1) * a.num_vertices + np.roll(f, -1, 1).reshape(-1)
    rev = np.roll(f, -1, 1).reshape(-1) * a.num_vertices + f.reshape(-1)
    assert len(np.unique(fwd)) == len(fwd) and np.isin(rev, fwd).all()
    labels = components(a.faces, a.num_vertices)
    v = a.vertices.astype(np.float64)
    for c in np.unique(labels):
        tri = v[f[labels[f[:, 0]] == c]]
        volume = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6
        assert volume > 0, "a part is inside out"
    # Smooth skinning: many vertices blend several bones, and neighbours have similar weights.
    assert (a.skin_weights[:, 1] > 0.05).mean() > 0.25
    dense = a.skin_weights_dense()
    e = np.concatenate([f[:, [0, 1]], f[:, [1, 2]]])
    assert np.percentile(np.abs(dense[e[:, 0]] - dense[e[:, 1]]).sum(1), 99) < 0.5
    # Clips: the plan's set, 30 fps, loops (the last frame leads into the first like any step).
    assert set(a.clips) == CLIPS[plan]
    for clip in a.clips.values():
        assert clip.fps == 30.0 and clip.num_frames >= 20
        posed = a.pose(clip.name, np.arange(clip.num_frames))
        steps = np.abs(np.diff(posed, axis=0)).max(axis=(1, 2))
        wrap = np.abs(posed[0] - posed[-1]).max()
        assert wrap <= 1.5 * steps.max() + 1e-9, clip.name
        assert steps.max() > 1e-3 * a.size(), f"{clip.name} does not move"
    # Standing animals touch the ground.
    if plan in LEGS:
        assert abs(a.vertices[:, 1].min()) < 0.03 * a.size()
        assert sum(1 for n in a.joint_names if n.endswith(("foot_l", "foot_r"))) == LEGS[plan]


def test_deterministic_for_a_seed():
    a, b = build_animal("bird", seed=3, jitter=0.05), build_animal("bird", seed=3, jitter=0.05)
    c = build_animal("bird", seed=4, jitter=0.05)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.vertex_colors, b.vertex_colors)
    for name in a.clips:
        np.testing.assert_array_equal(a.clips[name].rotations, b.clips[name].rotations)
    assert not np.allclose(a.vertices, c.vertices)
    assert [x.name for x in starter_assets(7, plans=["fish"])] == ["fish", "fish-deep"]


def test_proportion_parameters_shape_the_animal():
    base = PLANS["quadruped"][0]
    short = build_animal("quadruped", base)
    tall = build_animal(
        "quadruped", base.replace(leg_length=2 * base.leg_length, neck_length=2 * base.neck_length)
    )
    assert tall.bbox()[1][1] > short.bbox()[1][1] + 0.4  # longer legs and neck: taller
    long_snake = build_animal("snake", PLANS["snake"][0].replace(body_length=3.0))
    assert np.ptp(long_snake.vertices[:, 2]) == pytest.approx(3.0, rel=0.05)


def test_bad_plans_and_proportions_are_clear_errors():
    with pytest.raises(InputError, match="unknown body plan 'dragon'"):
        build_animal("dragon")
    with pytest.raises(InputError, match="girth must be positive"):
        build_animal("fish", BodyParams(0.5, 0, 0, 0.1, 0.1, 0.0))


def test_seed_bank_into_a_store(tmp_path):
    from zooctl.store.bank import Bank

    bank = Bank.open(tmp_path / "store")
    added = seed_bank(bank, seed=0, plans=["snake", "fish"], variants=False)
    assert added == ["snake", "fish"] and sorted(bank.names()) == ["fish", "snake"]
    assert seed_bank(bank, seed=0, plans=["snake"], variants=False) == []  # already there
    got = bank.get("snake")
    ref = build_animal("snake", PLANS["snake"][0].replace(), seed=0, name="snake", jitter=0.05)
    np.testing.assert_allclose(got.pose("slither", 5), ref.pose("slither", 5), atol=1e-6)


def test_cli_seed(store):
    r = zooctl("bank", "seed", "--plan", "spider", "--plan", "insect", "--json")
    assert r.code == 0, r.err
    assert r.json()["added"] == ["spider", "spider-longlegs", "insect", "insect-longlegs"]
    r = zooctl("bank", "list", "--json")
    assert {row["name"] for row in r.json()} == {"insect", "insect-longlegs", "spider", "spider-longlegs"}
    r = zooctl("bank", "seed", "--plan", "unicorn")
    assert r.code == 2 and "unknown body plan 'unicorn'" in r.err and "Traceback" not in r.err
