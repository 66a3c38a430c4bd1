"""Built-in articulation models: ``casa`` (stretchable bones + displacement field), ``dqs`` (the same
with dual-quaternion skinning) and ``lbs``."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ..components import ComponentSpec
from ..plugins import hookimpl

if TYPE_CHECKING:  # torch loads when a model is built, not when the plugin registers
    from ..asset import RiggedAsset
    from ..rig.base import ArticulationModel


def _casa(asset: RiggedAsset, device: str = "cpu", **options: Any) -> ArticulationModel:
    from ..rig.model import ArticulatedModel

    return ArticulatedModel(asset, device=device, **options)


def _dqs(asset: RiggedAsset, device: str = "cpu", **options: Any) -> ArticulationModel:
    from ..rig.dqs import DualQuaternionModel

    return DualQuaternionModel(asset, device=device, **options)


def _lbs(asset: RiggedAsset, device: str = "cpu", **options: Any) -> ArticulationModel:
    from ..rig.model import ArticulatedModel

    # plain LBS whatever the fit's ablation switches say
    options.update(stretch=False, displacement=False, girth=False)
    return ArticulatedModel(asset, device=device, **options)


@hookimpl
def register_articulation_models(register):
    register(
        ComponentSpec(
            "articulation_model",
            "casa",
            _casa,
            "CASA: FK with per-bone length scales, stretchable bones, softmax skinning, displacement MLP",
        )
    )
    register(
        ComponentSpec(
            "articulation_model",
            "dqs",
            _dqs,
            "CASA's model with dual-quaternion skinning (Kavan 2007): no candy-wrapper collapse at twists",
        )
    )
    register(
        ComponentSpec("articulation_model", "lbs", _lbs, "plain linear blend skinning with learnable weights")
    )
