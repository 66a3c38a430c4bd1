"""The fitted character (`RiggedAsset`) reproduces the fitted model, root motion and scale included."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from zooctl.fit.fitted_asset import fitted_asset
from zooctl.fit.scene import FitScene
from zooctl.retrieval.train_data import unweld
from zooctl.rig.rotations import quat_to_matrix
from zooctl.rig.synthetic import tube_asset


@pytest.mark.parametrize("bone_scale,tol", [(0.0, 1e-5), (0.2, 5e-3)])
def test_exported_asset_matches_the_model(bone_scale, tol):
    """Exact without stretch; with 20% longer bones, vertices blended between two stretched bones
    move by a fraction of a percent (plain LBS re-binding of CASA's stretch rule)."""
    tmpl = tube_asset(bones=3, name="tube")
    scene = FitScene(tmpl, 4, 32, 32, 40.0, hidden=16)
    g = torch.Generator().manual_seed(0)
    with torch.no_grad():
        scene.rotations.add_(0.2 * torch.randn(scene.rotations.shape, generator=g))
        scene.root_rotation.add_(0.3 * torch.randn(scene.root_rotation.shape, generator=g))
        scene.root_translation.copy_(torch.randn(4, 3, generator=g))
        scene.model.log_scale.fill_(0.3)
        scene.model.log_bone_scales.fill_(bone_scale)
    asset = fitted_asset(scene, tmpl, "fitted", 24.0)
    assert asset.clips["fit"].num_frames == 4 and asset.clips["fit"].fps == 24.0
    with torch.no_grad():
        want = scene.pose().vertices.numpy()
    err = np.abs(asset.pose("fit", np.arange(4)) - want).max() / tmpl.size()
    assert err < tol, err


def test_a_displaced_mesh_keeps_its_skeleton():
    """A displacement field that moves the whole mesh (what fits drift into) is the root's
    translation in the export, not a shift of the mesh off its bones: the exported posed mesh is
    the model's, and the skeleton moves with the mesh, in the model (`Pose.joints`) and the export."""
    tmpl = tube_asset(bones=3, name="tube")
    scene = FitScene(tmpl, 4, 32, 32, 40.0, hidden=16)
    g = torch.Generator().manual_seed(1)
    size = tmpl.size()
    shift = torch.tensor([0.08, -0.05, 0.03]) * size
    with torch.no_grad():
        scene.rotations.add_(0.4 * torch.randn(scene.rotations.shape, generator=g))
        scene.root_rotation.add_(0.3 * torch.randn(scene.root_rotation.shape, generator=g))
        scene.root_translation.copy_(torch.randn(4, 3, generator=g))
        bare = scene.pose()  # no displacement yet
        last = scene.model.displacement.mlp[-1]
        last.bias.copy_(shift / scene.model.displacement.extent)  # the mesh moved by ~10% of its size
        last.weight.normal_(0.0, 1e-4, generator=g)  # and a small change of shape
        pose = scene.pose()
        mean_d = scene.model.displacement(scene.model.global_scale() * scene.model.points).mean(0)
        R = quat_to_matrix(scene.root_rotation)  # (T, 3, 3), the model's own
    assert torch.linalg.norm(mean_d - shift) < 0.01 * size
    moved = bare.joints + (R @ mean_d)[:, None]
    assert torch.allclose(pose.joints, moved, atol=1e-4 * size), "the skeleton did not follow the mesh"
    asset = fitted_asset(scene, tmpl, "fitted", 24.0)
    err = np.abs(asset.pose("fit", np.arange(4)) - pose.vertices.numpy()).max() / size
    assert err < 2e-3, err
    clip = asset.clips["fit"]
    joints = asset.joint_transforms(clip.local_matrices())[..., :3, 3]
    assert np.abs(joints - pose.joints.numpy()).max() / size < 2e-3


def test_surface_tear_sees_stretched_edges_and_opened_seams_not_bending_or_scale():
    import dataclasses

    from zooctl.fit.outputs import surface_tear

    bent = tube_asset(bones=3, rings_per_bone=4, segments=8)
    bent = dataclasses.replace(bent, clips={"fit": bent.clips["bend"]})
    assert surface_tear(bent) == 0.0  # a smooth bend of up to 0.6 rad per joint tears nothing
    scales = bent.clips["fit"].scales.copy()
    scales[:, 0] *= 3.0  # the root's scale: the whole body three times its size
    big = dataclasses.replace(bent, clips={"fit": dataclasses.replace(bent.clips["fit"], scales=scales)})
    assert surface_tear(big) == 0.0  # the whole pose's scale is not a tear
    split = unweld(bent)
    assert surface_tear(split) == 0.0  # copies of a vertex that move together: a closed surface
    cracked = split.skin_joints.copy(), split.skin_weights.copy()
    far = split.vertices[:, 0] > 0.9 * split.vertices[:, 0].max()  # the tip ring's copies...
    first = far & (np.arange(split.num_vertices) % 3 == 0)  # ...one face-corner in three of them
    cracked[0][first], cracked[1][first] = 0, 0.0
    cracked[1][first, 0] = 1.0  # skinned to the root bone: left behind when the tube bends
    torn = dataclasses.replace(split, skin_joints=cracked[0], skin_weights=cracked[1])
    assert 0.0 < surface_tear(torn) < 0.5
    flat = dataclasses.replace(bent, faces=np.zeros((1, 3), np.int32))  # one face on one vertex
    assert surface_tear(flat) == 0.0


def test_surface_tear_finds_the_seams_on_the_template_when_the_rest_shape_is_already_cracked():
    """A fitted character's rest shape can be cracked (copies with different learned skinning,
    moved apart by stretched bones): its own rest positions no longer tell which vertices are
    copies of one, its template's do."""
    import dataclasses

    from zooctl.fit.outputs import surface_tear

    bent = tube_asset(bones=3, rings_per_bone=4, segments=8)
    split = unweld(dataclasses.replace(bent, clips={"fit": bent.clips["bend"]}))
    far = split.vertices[:, 0] > 0.9 * split.vertices[:, 0].max()
    first = far & (np.arange(split.num_vertices) % 3 == 0)
    edge = np.linalg.norm(split.vertices[split.faces[:, 0]] - split.vertices[split.faces[:, 1]], axis=1).max()
    rest = split.vertices.copy()
    rest[first, 0] += 3.0 * edge  # the tip's copies pulled out at rest: a gaping crack
    cracked = dataclasses.replace(split, vertices=rest)
    assert surface_tear(cracked) == 0.0  # blind: each pulled copy is its own position
    assert surface_tear(cracked, seams=split.vertices) > 0.0
    assert surface_tear(split, seams=split.vertices) == 0.0
    with pytest.raises(ValueError):
        surface_tear(split, seams=split.vertices[:-1])


def test_a_torn_fit_gets_a_note_that_says_what_to_do():
    from zooctl.fit.outputs import surface_tear_note

    assert surface_tear_note(0.013, 0.5) is None  # as much as an artist's clip tears at most
    note = surface_tear_note(0.063, 0.5)
    assert "6.3 %" in note and '"edge_stretch": 2}' in note and "(this fit: 0.5)" in note
