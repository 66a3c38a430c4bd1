"""Forward kinematics and stretchable LBS: numpy agreement and float64 gradchecks."""

import numpy as np
import torch

from zooctl import geometry
from zooctl.rig.kinematics import KinematicTree, compose_trs, forward_kinematics
from zooctl.rig.rotations import quat_normalize
from zooctl.rig.skinning import child_offset_shift, endpoint_weights, linear_blend_skinning, stretch_vectors

PARENTS = np.array([-1, 0, 1, 1, 0, 4, 2, -1, 7])  # branching, two roots


def _random_local(T, J, dtype=torch.float64, seed=0):
    g = torch.Generator().manual_seed(seed)
    t = torch.randn(T, J, 3, generator=g, dtype=dtype)
    q = quat_normalize(torch.randn(T, J, 4, generator=g, dtype=dtype))
    s = 0.5 + torch.rand(T, J, 3, generator=g, dtype=dtype)
    return t, q, s


def test_fk_matches_numpy_reference():
    t, q, s = _random_local(3, len(PARENTS))
    local = compose_trs(t, q, s)
    np.testing.assert_allclose(
        local.numpy(), geometry.compose_trs(t.numpy(), q.numpy(), s.numpy()), atol=1e-12
    )
    G = forward_kinematics(local, KinematicTree(PARENTS))
    np.testing.assert_allclose(G.numpy(), geometry.global_transforms(local.numpy(), PARENTS), atol=1e-10)


def test_fk_gradcheck():
    tree = KinematicTree(PARENTS)
    t, q, s = _random_local(2, len(PARENTS))
    args = tuple(x.requires_grad_(True) for x in (t, q, s))
    assert torch.autograd.gradcheck(lambda a, b, c: forward_kinematics(compose_trs(a, b, c), tree), args)


def test_stretch_and_lbs_gradcheck():
    g = torch.Generator().manual_seed(1)
    J, V, K = len(PARENTS), 12, 3
    heads = torch.randn(J, 3, generator=g, dtype=torch.float64)
    tails = heads + torch.randn(J, 3, generator=g, dtype=torch.float64)
    points = torch.randn(V, 3, generator=g, dtype=torch.float64)
    bones = torch.randint(0, J, (V, K), generator=g)
    parents = torch.as_tensor(PARENTS)
    child_e = torch.rand(J, generator=g, dtype=torch.float64)
    inv_bind = compose_trs(*[x[0] for x in _random_local(1, J, seed=3)])
    t, q, s = _random_local(2, J, seed=4)
    tree = KinematicTree(PARENTS)

    def f(log_b, logits, rot):
        st = stretch_vectors(log_b.exp(), heads, tails)
        tr = t + child_offset_shift(st, parents, child_e, inv_bind)
        mats = forward_kinematics(compose_trs(tr, rot, s), tree) @ inv_bind
        e = endpoint_weights(points[:, None, :], heads[bones], tails[bones])
        return linear_blend_skinning(points, mats, bones, torch.softmax(logits, -1), st, e)

    log_b = (0.3 * torch.randn(J, generator=g, dtype=torch.float64)).requires_grad_(True)
    logits = torch.randn(V, K, generator=g, dtype=torch.float64).requires_grad_(True)
    assert torch.autograd.gradcheck(f, (log_b, logits, q.clone().requires_grad_(True)))
    # endpoint weights w.r.t. the points themselves (away from the clamp kinks)
    pts = points.clone().requires_grad_(True)
    assert torch.autograd.gradcheck(
        lambda p: endpoint_weights(p[:, None, :], heads[bones], tails[bones]), (pts,)
    )


def test_lbs_dense_and_gathered_paths_agree(monkeypatch):
    """Skeletons up to DENSE_MAX_JOINTS blend through dense weights; bigger ones gather: same result."""
    from zooctl.rig import skinning

    g = torch.Generator().manual_seed(3)
    B, V, J, K = 2, 50, 9, 3
    points = torch.randn(V, 3, generator=g, dtype=torch.float64)
    mats = torch.randn(B, J, 4, 4, generator=g, dtype=torch.float64)
    bones = torch.stack([torch.randperm(J, generator=g)[:K] for _ in range(V)])
    w = torch.softmax(torch.randn(V, K, generator=g, dtype=torch.float64), -1)
    st = torch.randn(B, J, 3, generator=g, dtype=torch.float64)
    e = torch.rand(V, K, generator=g, dtype=torch.float64)
    dense = linear_blend_skinning(points, mats, bones, w, st, e)
    monkeypatch.setattr(skinning, "DENSE_MAX_JOINTS", 0)
    gathered = linear_blend_skinning(points, mats, bones, w, st, e)
    assert dense.shape == (B, V, 3)
    torch.testing.assert_close(dense, gathered)


def test_lbs_skins_many_poses_a_few_at_a_time_with_the_same_result(monkeypatch):
    """A long clip's poses are skinned in chunks (the per-vertex matrices of 2,400 frames of a
    4,000-vertex mesh took 4.9 GB at once): the same numbers for any chunk size and shape."""
    import zooctl.asset as asset_mod

    rng = np.random.default_rng(0)
    V, K, J = 40, 3, 5
    v, sj, sw = rng.normal(size=(V, 3)), rng.integers(0, J, (V, K)), rng.random((V, K))
    mats = rng.normal(size=(2, 7, J, 4, 4))
    whole = asset_mod.lbs(v, sj, sw, mats)
    monkeypatch.setattr(asset_mod, "LBS_CHUNK_BYTES", 1)  # one pose at a time
    assert whole.shape == (2, 7, V, 3) and np.array_equal(asset_mod.lbs(v, sj, sw, mats), whole)
    assert np.array_equal(asset_mod.lbs(v, sj, sw, mats[1, 3]), whole[1, 3])


def _fk_level_by_level(local, parents):
    out = [None] * len(parents)
    for j, p in enumerate(parents):
        out[j] = local[..., j, :, :] if p < 0 else out[p] @ local[..., j, :, :]
    return torch.stack(out, -3)


def test_pointer_jumping_fk_takes_log_depth_rounds_and_agrees():
    """A 40-deep chain, random trees and lone roots: the rounds are ceil(log2(depth + 1)) and the
    transforms those of the parent-by-parent products, values and gradients."""
    rng = np.random.default_rng(5)
    cases = [
        [-1] + list(range(39)),  # a chain: depth 39
        [-1] + [int(rng.integers(0, j)) for j in range(1, 60)],
        [-1, -1, -1],
        [-1],
    ]
    for parents in cases:
        tree = KinematicTree(parents)
        depth = np.zeros(len(parents), int)
        for j, p in enumerate(parents):
            depth[j] = 0 if p < 0 else depth[p] + 1
        assert len(tree.jumps) == int(np.ceil(np.log2(depth.max() + 1)))
        t, q, s = _random_local(2, len(parents), seed=len(parents))
        local = compose_trs(t, q, 0.9 + 0.2 * s).requires_grad_(True)
        got = forward_kinematics(local, tree)
        want = _fk_level_by_level(local, parents)
        torch.testing.assert_close(got, want, rtol=1e-10, atol=1e-10)
        w = torch.randn(got.shape, dtype=got.dtype, generator=torch.Generator().manual_seed(0))
        (g_got,) = torch.autograd.grad((got * w).sum(), local)
        (g_want,) = torch.autograd.grad((want * w).sum(), local)
        torch.testing.assert_close(g_got, g_want, rtol=1e-9, atol=1e-9)


def test_fk_operators_grow_with_the_log_of_the_depth():
    """What a GPU pays for in launches: a 63-deep chain's forward kinematics runs a handful of
    operators (6 rounds of two, and the identity past the roots), not one set per level."""
    from torch.utils._python_dispatch import TorchDispatchMode

    views = {
        "view",
        "_unsafe_view",
        "reshape",
        "expand",
        "slice",
        "select",
        "unsqueeze",
        "as_strided",
        "alias",
        "detach",
    }
    ops = []

    class Count(TorchDispatchMode):
        def __torch_dispatch__(self, func, types, args=(), kwargs=None):
            if func.overloadpacket.__name__ not in views:
                ops.append(func.overloadpacket.__name__)
            return func(*args, **(kwargs or {}))

    tree = KinematicTree([-1] + list(range(63)))
    local = torch.randn(4, 64, 4, 4)
    with Count():
        forward_kinematics(local, tree)
    assert len(tree.jumps) == 6
    assert len(ops) <= 2 * 6 + 2, ops
