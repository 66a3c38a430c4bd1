"""The fitted character (`RiggedAsset`) reproduces the fitted model, root motion and scale included."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from zooctl.fit.export import fitted_asset
from zooctl.fit.scene import FitScene
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
