"""Fit, bench and config validation take renderer and articulation-model names from the plugin
registry: a plugin's component is accepted and used, an unknown name is one clear error."""

from __future__ import annotations

import json

import pytest
import torch
from cli_helpers import REPO, zooctl

from zooctl import plugins
from zooctl.components import ComponentSpec
from zooctl.errors import UsageError
from zooctl.fit.config import FitConfig
from zooctl.plugins import PluginManager, hookimpl


class CountingSoft:
    """A plugin renderer: the soft silhouette renderer that counts its calls."""

    calls = 0

    @hookimpl
    def register_renderers(self, register):
        def factory(image_size, device="cpu", **options):
            from zooctl.render.soft import SoftSilhouette

            inner = SoftSilhouette(image_size, sigma=0.05)

            def render(vertices, faces, camera):
                CountingSoft.calls += 1
                return inner(vertices, faces, camera)

            return render

        register(ComponentSpec("renderer", "counting", factory, "soft, counted"))


@pytest.fixture
def with_plugin(monkeypatch):
    pm = PluginManager()
    pm.load_entry_points()
    pm.register(CountingSoft(), "counting")
    monkeypatch.setattr(plugins, "_MANAGER", pm)
    return pm


def test_unknown_names_are_one_clear_error():
    with pytest.raises(UsageError, match="no renderer named 'nope'") as exc:
        FitConfig.from_dict({"stage2": {"renderer": "nope"}})
    assert "soft" in exc.value.hint and "fast" in exc.value.hint
    with pytest.raises(UsageError, match="no articulation model named 'bones'") as exc:
        FitConfig.from_dict({"articulation": "bones"})
    assert "casa" in exc.value.hint and "dqs" in exc.value.hint
    for flag in ("--renderer", "--articulation"):
        r = zooctl("fit", "any-video", flag, "nope", store=REPO / "no-such-store")
        assert r.code == 2 and "named 'nope'" in r.err and "Traceback" not in r.err, r.err
    r = zooctl("fit", "any-video", "--renderer", "flow", "--template", "x", store=REPO / "no-such-store")
    assert r.code == 2 and "Traceback" not in r.err


def test_flow_renderer_is_refused_as_a_silhouette():
    from zooctl.render.base import check_silhouette, get_renderer, renders_flow

    assert renders_flow(get_renderer("flow", 8)) and not renders_flow(get_renderer("soft", 8))
    with pytest.raises(UsageError, match="does not render silhouettes"):
        check_silhouette("flow", {"flow": None}, 1, 8, 8)


def test_plugin_renderer_passes_validation_and_the_schema_and_is_used(with_plugin):
    import jsonschema

    from zooctl.asset import RiggedAsset  # noqa: F401  (the template below is a real rig)
    from zooctl.fit.losses import MaskTargets
    from zooctl.fit.scene import FitScene
    from zooctl.fit.stages import StageRunner, Targets
    from zooctl.rig.synthetic import tube_asset

    cfg = FitConfig.from_dict({"stage1": {"renderer": "counting"}, "articulation": "dqs"})
    schema = json.loads((REPO / "schemas" / "fit_config.schema.json").read_text())
    jsonschema.Draft202012Validator(schema).validate(cfg.to_dict())
    asset = tube_asset(bones=3, rings_per_bone=2, segments=8, bone_length=0.3, radius=0.05)
    scene = FitScene(asset, 2, 16, 16, focal=20.0, articulation=cfg.articulation, hidden=8)
    assert type(scene.model).__name__ == "DualQuaternionModel"
    with torch.no_grad():
        scene.root_translation[:, 2] = -2.0
    targets = Targets(MaskTargets.build((torch.rand(2, 16, 16).numpy() > 0.5).astype("float32"), seed=0))
    runner = StageRunner(scene, targets, cfg, 1)
    before = CountingSoft.calls
    total, _ = runner.loss(torch.arange(2))
    assert CountingSoft.calls == before + 1 and torch.isfinite(total)


def test_old_dt_weight_is_read_as_contour_with_a_warning():
    with pytest.warns(FutureWarning, match="weights.dt is deprecated"):
        cfg = FitConfig.from_dict({"weights": {"dt": 0.25}})
    assert cfg.weights.contour == 0.25 and "dt" not in cfg.to_dict()["weights"]
    with pytest.raises(UsageError, match="both 'dt' and its new name 'contour'"):
        FitConfig.from_dict({"weights": {"dt": 0.25, "contour": 0.5}})


def test_bench_takes_component_names(tmp_path):
    r = zooctl("bench", "run", str(tmp_path), "--articulation", "nope", store=tmp_path / "s")
    assert r.code == 2 and "no articulation model named 'nope'" in r.err and "Traceback" not in r.err
    r = zooctl(
        "bench",
        "rig",
        "--articulation",
        "dqs",
        "--vertices",
        "200",
        "--joints",
        "4",
        "--frames",
        "2",
        "--repeats",
        "1",
        "--json",
    )
    assert r.code == 0, r.err
    assert r.json()["benchmark"] == "fk+dqs" and r.json()["ms_per_frame"] > 0
