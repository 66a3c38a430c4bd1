"""ArticulatedModel: reproduces imported assets, stretches only what it should, stays continuous."""

from pathlib import Path

import numpy as np
import pytest
import torch

from zooctl.retrieval.train_data import unweld
from zooctl.rig.model import ArticulatedModel
from zooctl.rig.rotations import axis_angle_to_quat
from zooctl.rig.synthetic import tube_asset

ASSETS = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "assets" / "quaternius"
SAMPLE = ["animals_pack/Fox.glb", "dinosaurs_pack/Trex.glb", "easy_enemies_pack/Spider.glb"]
needs_assets = pytest.mark.skipif(
    not ASSETS.is_dir(), reason=f"shared Quaternius assets not found at {ASSETS}"
)


def _load(rel: str):
    from zooctl.io.gltf_import import load_gltf

    return load_gltf(ASSETS / rel, Path(rel).stem)


@needs_assets
@pytest.mark.parametrize("rel", SAMPLE)
def test_reproduces_imported_clip_vertices(rel):
    asset = _load(rel)
    model = ArticulatedModel(asset, dtype=torch.float64)  # unit scales, zero displacement
    for clip in list(asset.clips.values())[:2]:
        frames = np.arange(0, clip.num_frames, max(1, clip.num_frames // 6))
        ref = asset.pose(clip.name, frames)
        with torch.no_grad():
            out = model(
                torch.as_tensor(clip.rotations[frames]),
                translations=torch.as_tensor(clip.translations[frames]),
                scales=torch.as_tensor(clip.scales[frames]),
            )
        assert np.abs(out.vertices.numpy() - ref).max() < 1e-5


@needs_assets
def test_stretched_skeleton_and_mesh_agree_at_every_joint():
    """Continuity: at each joint head, the parent's stretched transform and the child's agree."""
    asset = _load("animals_pack/Fox.glb")
    model = ArticulatedModel(asset, dtype=torch.float64, displacement=False)
    g = torch.Generator().manual_seed(0)
    with torch.no_grad():
        model.log_bone_scales.copy_(0.3 * torch.randn(asset.num_joints, generator=g, dtype=torch.float64))
    rot = axis_angle_to_quat(0.4 * torch.randn(2, asset.num_joints, 3, generator=g, dtype=torch.float64))
    with torch.no_grad():
        pose = model(rot)
    mats = pose.transforms @ model.inverse_bind
    s = (model.bone_scales() - 1)[:, None] * (model.tails - model.heads)
    skinned = asset.skin_weights_dense().sum(0) > 0
    checked = 0
    for j in range(1, asset.num_joints):
        p = int(model.parents[j])
        if p < 0 or not skinned[p]:
            continue  # a parent that skins no vertex (the armature node) has no mesh to be continuous with
        checked += 1
        c = model.heads[j]
        e = model.child_e[j]
        by_parent = mats[:, p, :3, :3] @ (c + e * s[p]) + mats[:, p, :3, 3]
        by_child = mats[:, j, :3, :3] @ c + mats[:, j, :3, 3]
        assert torch.allclose(by_parent, by_child, atol=1e-6 * asset.size()), asset.joint_names[j]
    assert checked > 30


def test_stretching_one_bone_moves_only_its_vertices():
    asset = tube_asset(bones=3, rings_per_bone=8, blend=0.25)
    model = ArticulatedModel(asset, dtype=torch.float64, displacement=False)
    dense = asset.skin_weights_dense()
    x = asset.vertices[:, 0]
    rest = model().vertices.detach().numpy()
    np.testing.assert_allclose(rest, asset.vertices, atol=1e-6)
    with torch.no_grad():
        model.log_bone_scales[1] = np.log(1.5)  # the middle bone: [1, 2] along x
        moved = model().vertices.numpy()
    delta = moved - asset.vertices
    untouched = (dense[:, 1] == 0) & (x <= 1.0 + 1e-6)
    assert np.abs(delta[untouched]).max() < 1e-7  # the first bone's own vertices stay put
    beyond = (dense[:, 2] > 0.999) & (x > 2.0)
    np.testing.assert_allclose(
        delta[beyond], np.tile([0.5, 0.0, 0.0], (beyond.sum(), 1)), atol=1e-7
    )  # carried rigidly
    inside = dense[:, 1] > 0.999
    expected = 0.5 * np.clip(x[inside] - 1.0, 0.0, 1.0)  # e_k(p) * (b - 1) * |d - c|
    np.testing.assert_allclose(delta[inside, 0], expected, atol=1e-7)
    assert np.abs(delta[:, 1:]).max() < 1e-7  # a straight tube stretches only along its axis
    # No tearing: edges stay short where the mesh crosses the joints.
    e = asset.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    assert (
        np.linalg.norm(moved[e[:, 0]] - moved[e[:, 1]], axis=1).max()
        < 1.6 * np.linalg.norm(asset.vertices[e[:, 0]] - asset.vertices[e[:, 1]], axis=1).max()
    )


def test_weights_stay_on_simplex_and_displacement_and_root():
    asset = tube_asset(bones=2)
    model = ArticulatedModel(asset, hidden=32)
    rot = axis_angle_to_quat(torch.tensor([[0.0, 0.0, 0.0], [0.0, 0.0, 0.5]])).expand(3, 2, 4)
    opt = torch.optim.Adam(model.parameters(), lr=0.1)
    for _ in range(5):
        opt.zero_grad()
        out = model(rot)
        (out.vertices[..., 1].square().mean() + model.symmetry_loss() + model.bone_length_loss()).backward()
        opt.step()
    w = model.skin()
    assert torch.allclose(w.sum(-1), torch.ones(len(w)), atol=1e-5) and (w >= 0).all()
    # eq. 3 with a fresh field: v' = u v; then the root transform on top
    fresh = ArticulatedModel(asset, hidden=16)
    with torch.no_grad():
        fresh.log_scale.fill_(np.log(2.0))
        base = fresh().vertices
        assert torch.allclose(base, 2.0 * torch.as_tensor(asset.vertices), atol=1e-5)
        q = axis_angle_to_quat(torch.tensor([0.0, np.pi / 2, 0.0]))
        posed = fresh(root_rotation=q, root_translation=torch.tensor([1.0, 2.0, 3.0]))
        expect = torch.stack((base[:, 2], base[:, 1], -base[:, 0]), -1) + torch.tensor([1.0, 2.0, 3.0])
        assert torch.allclose(posed.vertices, expect, atol=1e-5)
        assert posed.joints.shape == (2, 3)


def test_plugin_registry_builds_models():
    from zooctl.plugins import get_registry

    reg = get_registry()
    asset = tube_asset(bones=2)
    casa = reg.get("articulation_model", "casa").create(asset=asset, hidden=16)
    lbs = reg.get("articulation_model", "lbs").create(asset=asset)
    assert casa.stretch and casa.displacement is not None
    assert not lbs.stretch and lbs.displacement is None
    assert lbs(axis_angle_to_quat(torch.zeros(4, 2, 3))).vertices.shape == (4, asset.num_vertices, 3)


def test_shared_displacement_runs_the_field_once_with_the_same_gradients():
    """One loss that poses the model, takes the symmetry term and the displacement prior: inside
    `shared_displacement` the field runs once, and every parameter's gradient is what three
    separate evaluations give (to float rounding)."""
    asset = tube_asset(bones=2)
    model = ArticulatedModel(asset, hidden=16, dtype=torch.float64)
    with torch.no_grad():
        for p in model.displacement.parameters():
            p.normal_(0.0, 0.3, generator=torch.Generator().manual_seed(0))
    rot = axis_angle_to_quat(torch.tensor([[0.0, 0.0, 0.0], [0.0, 0.3, 0.5]], dtype=torch.float64)).expand(
        3, 2, 4
    )
    calls = []
    model.displacement.register_forward_hook(lambda *_: calls.append(1))

    def loss():
        d = model.displacement_offsets()
        return model(rot).vertices.square().mean() + model.symmetry_loss() + d.square().mean()

    grads = []
    for shared in (False, True):
        model.zero_grad()
        calls.clear()
        if shared:
            with model.shared_displacement():
                with model.shared_displacement():  # nested: still the outer block's evaluation
                    value = loss()
        else:
            value = loss()
        value.backward()
        grads.append((value.detach(), [p.grad.clone() for p in model.parameters() if p.grad is not None]))
        assert len(calls) == (1 if shared else 3)
    (a, ga), (b, gb) = grads
    assert torch.allclose(a, b, rtol=1e-12) and len(ga) == len(gb) > 3
    assert all(torch.allclose(x, y, rtol=1e-9, atol=1e-12) for x, y in zip(ga, gb))
    assert model.displacement_offsets() is not model.displacement_offsets()  # off after the block


def test_seam_groups_join_copies_at_one_position_with_the_same_bones():
    from zooctl.rig.skinning import seam_groups

    points = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 0], [1, 0, 1e-9], [0, 0, 0]], float)
    bones = np.array([[0, 1], [1, 0], [0, 1], [1, 0], [1, 0]])
    # 2 is 0's copy, 3 is 1's (within the tolerance); 4 sits at 0 but blends other bones.
    assert seam_groups(points, bones).tolist() == [0, 1, 0, 1, 2]


@pytest.mark.parametrize("share", [True, False])
def test_learned_skinning_keeps_a_split_surface_closed_only_when_seams_are_shared(share):
    """Skinning learned per copy opens cracks between a flat-shaded mesh's faces; shared per
    position, the copies move as one vertex (what the exported character shows)."""
    from zooctl.rig.skinning import seam_groups

    asset = unweld(tube_asset(bones=3, rings_per_bone=2, segments=8))
    model = ArticulatedModel(asset, share_seams=share)
    groups = torch.as_tensor(seam_groups(asset.vertices.astype(np.float64), model.skin.bones.numpy()))
    assert (model.skin.logits.shape[0] < asset.num_vertices) == share
    g = torch.Generator().manual_seed(0)
    pull = torch.randn(asset.num_vertices, 3, generator=g)  # a different pull on every copy
    opt = torch.optim.Adam([model.skin.logits], lr=0.1)
    rot = model.rest_rotation.clone()
    rot[1] = axis_angle_to_quat(torch.tensor([0.0, 0.0, 0.8]))
    for _ in range(20):
        opt.zero_grad()
        (model(rot).vertices * pull).sum().backward()
        opt.step()
    with torch.no_grad():
        v = model(rot).vertices
    first = torch.as_tensor(np.unique(groups.numpy(), return_index=True)[1])  # a vertex per group
    spread = (v - v[first[groups]]).norm(dim=-1).max()  # how far copies of a vertex moved apart
    assert (spread < 1e-5) == share


def test_a_model_state_saved_with_a_row_per_vertex_loads_as_their_mean():
    """A state with a row of skin logits per copy (saved without shared seams) loads with them."""
    asset = unweld(tube_asset(bones=2, rings_per_bone=2, segments=6))
    old = ArticulatedModel(asset, share_seams=False)
    with torch.no_grad():
        old.skin.logits.add_(torch.randn_like(old.skin.logits))
    state = {k: v for k, v in old.state_dict().items() if k != "skin.groups"}
    new = ArticulatedModel(asset, share_seams=True)
    new.load_state_dict(state)
    g = new.skin.groups
    want = torch.zeros_like(new.skin.logits).index_add_(0, g, old.skin.logits.detach())
    want /= torch.bincount(g)[:, None].float()
    torch.testing.assert_close(new.skin.logits.detach(), want)


def test_a_fit_state_saved_with_a_row_per_vertex_resumes():
    from zooctl.fit.scene import FitScene

    asset = unweld(tube_asset(bones=2, rings_per_bone=2, segments=6))
    old = FitScene(asset, 3, 16, 16, focal=20.0, hidden=8, share_seams=False)
    state = {k: v for k, v in old.state_dict().items() if not k.endswith("groups")}
    new = FitScene(asset, 3, 16, 16, focal=20.0, hidden=8, share_seams=True)
    new.load_state_dict(state)
    assert new.init_logits.shape == new.model.skin.logits.shape
    torch.testing.assert_close(new.model.skin(), old.model.skin(), atol=1e-6, rtol=0)  # copies started equal


def test_girth_thickens_one_bone_across_its_axis_in_every_direction():
    asset = tube_asset(bones=3, rings_per_bone=8, blend=0.25)
    model = ArticulatedModel(asset, dtype=torch.float64, displacement=False, girth=True)
    np.testing.assert_allclose(model().vertices.detach().numpy(), asset.vertices, atol=1e-9)
    dense = asset.skin_weights_dense()
    with torch.no_grad():
        model.log_bone_girth[1] = np.log(1.5)  # the middle bone: [1, 2] along x
        moved = model().vertices.numpy()
    inside = (dense[:, 1] > 0.999) & (asset.vertices[:, 0] > 1.0) & (asset.vertices[:, 0] < 2.0)
    assert inside.sum() > 10
    radius = np.linalg.norm(asset.vertices[inside, 1:], axis=1)
    # Every ring vertex 1.5 times as far from the axis, in y (what a side view shows) and z alike.
    np.testing.assert_allclose(np.linalg.norm(moved[inside, 1:], axis=1), 1.5 * radius, rtol=1e-6)
    np.testing.assert_allclose(moved[inside, 0], asset.vertices[inside, 0], atol=1e-9)
    np.testing.assert_allclose(moved[inside, 1:], 1.5 * asset.vertices[inside, 1:], atol=1e-6)
    far = dense[:, 1] == 0
    np.testing.assert_allclose(moved[far], asset.vertices[far], atol=1e-9)  # other bones' vertices stay
    # The rest shape the exporter and the symmetry term read carries it too.
    np.testing.assert_allclose(model.canonical_vertices().detach().numpy(), moved, atol=1e-9)
    # Its prior: zero at the template, and it grows with the girth.
    assert float(model.bone_length_loss()) > 0


def test_girth_is_learned_with_the_shape_and_kept_by_keep_shape():
    from zooctl.fit.config import FitConfig
    from zooctl.fit.run import new_scene

    asset = tube_asset(bones=2)
    scene = new_scene(asset, FitConfig(), 4, 32, 32, (16.0, 16.0))
    assert any(p is scene.model.log_bone_girth for p in scene.shape_parameters())
    kept = FitConfig().keep_shape()
    assert not kept.ablation.girth
    assert new_scene(asset, kept, 4, 32, 32, (16.0, 16.0)).model.log_bone_girth is None
    off = FitConfig.from_dict({"ablation": {"girth": False}})
    assert new_scene(asset, off, 4, 32, 32, (16.0, 16.0)).model.log_bone_girth is None


def test_a_state_saved_before_girths_loads_with_every_girth_at_one():
    asset = tube_asset(bones=3)
    old = ArticulatedModel(asset, dtype=torch.float64)
    with torch.no_grad():
        old.log_bone_scales[1] = 0.3
    state = old.state_dict()
    assert not any("girth" in k for k in state)
    new = ArticulatedModel(asset, dtype=torch.float64, girth=True)
    new.load_state_dict(state)  # strict: nothing missing, nothing left over
    assert float(new.log_bone_girth.abs().max()) == 0.0
    torch.testing.assert_close(new().vertices, old().vertices)
    assert not any("girth_radial" in k for k in new.state_dict())


def test_lengthen_makes_the_body_longer_along_its_axis_and_the_prior_holds_it_there():
    """`lengthen` (the template trials' longer body): a tube along x, every bone along its axis,
    comes out that much longer and no thicker; the bone-length prior is zero there, not at the
    template's lengths, and a state saved before the prior's centre existed loads at the template."""
    asset = tube_asset(bones=3)
    model = ArticulatedModel(asset, dtype=torch.float64, displacement=False)
    before = model().vertices.detach()
    model.lengthen(1.3)
    after = model().vertices.detach()
    ext0, ext1 = before.amax(0) - before.amin(0), after.amax(0) - after.amin(0)
    assert float(ext1[0] / ext0[0]) == pytest.approx(1.3, rel=1e-6)
    torch.testing.assert_close(ext1[1:], ext0[1:])
    assert float(model.bone_length_loss().detach()) == pytest.approx(0.0, abs=1e-12)
    with torch.no_grad():
        model.log_bone_scales.zero_()  # the template's own lengths are now off the prior's centre
    assert float(model.bone_length_loss().detach()) > 0.01
    state = {k: v for k, v in model.state_dict().items() if k != "bone_centre"}
    old = ArticulatedModel(asset, dtype=torch.float64, displacement=False)
    old.load_state_dict(state)  # strict
    assert float(old.bone_centre.abs().max()) == 0.0
    kept = ArticulatedModel(asset, dtype=torch.float64, displacement=False)
    kept.load_state_dict(model.state_dict())  # a paused longer trial resumes with its centre
    torch.testing.assert_close(kept.bone_centre, model.bone_centre)


def test_lengthen_leaves_a_bone_across_the_body_as_it_is():
    """Only bones along the body's longest axis grow, by ``factor ** cos^2`` of their angle to it:
    a bone at right angles (a leg) keeps its length. The tube's bones are turned in the model's
    buffers alone, so the axis (its vertices') stays along x."""
    tube = tube_asset(bones=3)
    model = ArticulatedModel(tube, dtype=torch.float64, displacement=False)
    with torch.no_grad():
        model.tails[1] = model.heads[1] + torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64)
        model.tails[2] = model.heads[2] + torch.tensor([1.0, 1.0, 0.0], dtype=torch.float64)
    model.lengthen(2.0)
    scales = model.bone_scales().detach()
    assert float(scales[1]) == pytest.approx(1.0, abs=1e-9)  # across
    assert float(scales[2]) == pytest.approx(2.0**0.5, rel=1e-6)  # 45 degrees: cos^2 = 1/2
    assert float(scales[0]) == pytest.approx(2.0, rel=1e-6)  # along


def test_the_field_runs_once_per_bind_position_with_the_same_offsets_and_gradients():
    """Copies of a vertex at one bind position (an unwelded, flat-shaded surface) read the field
    once: the offsets of every vertex and the MLP's gradients are those of the field run on all of
    them, and nothing new is saved (earlier fit states load)."""
    asset = unweld(tube_asset(bones=3, rings_per_bone=2, segments=8, bone_length=0.3, radius=0.05))
    torch.manual_seed(0)
    model = ArticulatedModel(asset, hidden=16)
    assert len(model.field_index) < model.num_vertices  # the unwelded copies share positions
    for p in model.displacement.parameters():
        p.data.normal_(0.0, 0.3)
    got = model.displacement_offsets()
    want = model.displacement(model.global_scale() * model.points)
    torch.testing.assert_close(got, want, rtol=0, atol=0)
    w = torch.randn_like(want)
    params = list(model.displacement.parameters())
    for a, b in zip(
        torch.autograd.grad((got * w).sum(), params),
        torch.autograd.grad((want * w).sum(), params),
        strict=True,
    ):
        torch.testing.assert_close(a, b, rtol=1e-5, atol=1e-6)
    assert not any(k.startswith("field_") for k in model.state_dict())


def _posed_every_vertex(model: ArticulatedModel) -> ArticulatedModel:
    """The same model posing each vertex itself (as before the surface rows existed)."""
    import copy

    ref = copy.deepcopy(model)
    ref.surface_index = None
    return ref


@pytest.mark.parametrize("skinning", ["casa", "dqs"])
def test_the_surface_is_posed_once_per_seam_copy_group_with_the_same_vertices_and_gradients(skinning):
    """Copies of a vertex with the same position, bones, weights and girth directions are posed
    once and gathered: every posed vertex and every parameter's gradient are those of posing
    each vertex, through both skinnings, with the root and the field on; nothing new is saved."""
    from zooctl.rig.dqs import DualQuaternionModel

    cls = ArticulatedModel if skinning == "casa" else DualQuaternionModel
    asset = unweld(tube_asset(bones=3, rings_per_bone=2, segments=8, bone_length=0.3, radius=0.05))
    torch.manual_seed(0)
    model = cls(asset, hidden=16, dtype=torch.float64, share_seams=True, girth=True)
    assert model.surface_index is not None and len(model.surface_index) < model.num_vertices
    with torch.no_grad():
        for p in model.parameters():
            p.add_(0.2 * torch.randn_like(p))
    ref = _posed_every_vertex(model)
    T, J = 3, model.num_joints
    rot = axis_angle_to_quat(0.4 * torch.randn(T, J, 3, dtype=torch.float64))
    root = axis_angle_to_quat(torch.randn(T, 3, dtype=torch.float64))
    shift = torch.randn(T, 3, dtype=torch.float64)
    got, want = model(rot, root, shift), ref(rot, root, shift)
    torch.testing.assert_close(got.vertices, want.vertices, rtol=1e-10, atol=1e-12)
    torch.testing.assert_close(got.joints, want.joints, rtol=1e-10, atol=1e-12)
    w = torch.randn_like(want.vertices)
    for (name, a), b in zip(
        model.named_parameters(),
        torch.autograd.grad((want.vertices * w).sum(), list(ref.parameters())),
        strict=True,
    ):
        (ga,) = torch.autograd.grad((model(rot, root, shift).vertices * w).sum(), [a])
        torch.testing.assert_close(ga, b, rtol=1e-9, atol=1e-11, msg=name)
    assert not any(k.startswith("surface_") for k in model.state_dict())
    assert model.state_dict().keys() == ref.state_dict().keys()


def test_the_surface_rows_keep_apart_copies_whose_skinning_differs():
    """Without shared seams each copy learns its own weights: no rows are shared. With them, a
    copy whose template weights differ (so its girth moves it differently) gets its own row."""
    import dataclasses

    asset = unweld(tube_asset(bones=2, rings_per_bone=2, segments=6))
    assert ArticulatedModel(asset, share_seams=False).surface_index is None
    shared = ArticulatedModel(asset, share_seams=True, girth=True)
    rows = len(shared.surface_index)
    w = asset.skin_weights.copy()
    mixed = int(np.nonzero(w.max(1) < 0.9)[0][0])  # a vertex between two bones
    same = torch.nonzero(shared.surface_inverse == shared.surface_inverse[mixed]).flatten()
    assert len(same) > 1  # it has copies
    twin = int(same[-1])
    top = int(np.argmax(w[twin]))
    w[twin] *= 0.5
    w[twin, top] += 0.5  # more weight on its main bone: other girth directions, same bones
    changed = dataclasses.replace(asset, skin_weights=w)
    assert len(ArticulatedModel(changed, share_seams=True, girth=True).surface_index) == rows + 1
    assert len(ArticulatedModel(changed, share_seams=True, girth=False).surface_index) == rows


@needs_assets
def test_the_wolf_is_posed_at_a_quarter_of_its_vertices():
    model = ArticulatedModel(_load("animals_pack/Wolf.glb"), share_seams=True, girth=True)
    assert len(model.surface_index) <= 0.3 * model.num_vertices


def test_a_model_with_surface_rows_pickles_and_its_rows_follow_a_loaded_state():
    """The model crosses process boundaries (the trials side by side) and loads fit states: it
    pickles (no closures among its hooks), and its rows follow the weight groups a state brings
    (here the same groups numbered another way, the logits' rows with them)."""
    import pickle

    asset = unweld(tube_asset(bones=2, rings_per_bone=2, segments=6))
    torch.manual_seed(0)
    model = ArticulatedModel(asset, share_seams=True, girth=True)
    with torch.no_grad():
        model.skin.logits.normal_()
    again = pickle.loads(pickle.dumps(model))
    torch.testing.assert_close(again().vertices, model().vertices, rtol=0, atol=0)
    state = model.state_dict()
    U = state["skin.logits"].shape[0]
    perm = torch.randperm(U)  # new id of each old group
    state["skin.groups"] = perm[state["skin.groups"]]
    logits = torch.empty_like(state["skin.logits"])
    logits[perm] = state["skin.logits"]
    state["skin.logits"] = logits
    fresh = ArticulatedModel(asset, share_seams=True, girth=True)
    fresh.load_state_dict(state)
    torch.testing.assert_close(fresh().vertices, model().vertices, rtol=0, atol=0)
