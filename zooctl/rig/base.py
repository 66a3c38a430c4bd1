"""The articulation-model interface, and the one way the rest of zooctl builds one: by its name in
the plugin registry (`zooctl.hookspecs.register_articulation_models`).

A factory is called as ``factory(asset, device="cpu", **options)``; the fit passes the options
``stretch``, ``displacement`` (its ablation switches), ``hidden`` (displacement MLP width),
``share_seams`` (copies of a vertex learn one skinning row) and ``girth`` (bones that also thicken
across themselves, ``log_bone_girth`` (J,)), which a model may ignore; a factory
that names its options and takes no ``**options`` gets only those it names. The object is a
``torch.nn.Module`` with:

- ``forward(rotations (..., J, 4) wxyz, root_rotation (..., 4), root_translation (..., 3))`` ->
  `zooctl.rig.model.Pose` with ``vertices`` (..., V, 3), ``joints`` (..., J, 3) and ``transforms``
  (..., J, 4, 4); ``...`` is the frame batch (T,). All arguments default to the rest pose.
- buffers ``points`` (V, 3) bind vertices, ``faces`` (F, 3) long, ``rest_rotation`` (J, 4);
  ``num_joints``, ``num_vertices``;
- learnable shape: ``log_scale`` () (``global_scale()`` = its exp), ``log_bone_scales`` (J,),
  ``skin.logits`` (V, K), or (U, K) a row per group of vertices sharing their weights, with
  ``skin()`` the (V, K) weights, and ``displacement`` (an ``nn.Module`` of (V, 3) points, or None);
- the priors the fit weights: ``symmetry_loss(sample)``, ``bone_length_loss()``,
  ``smoothness_loss(rotations)`` (scalars), and ``canonical_vertices()`` (V, 3);
- optionally ``mirrored_joints()`` -> (normal (3,), offset (), pairs (P, 2)): the rest shape's mirror
  plane and the joints that mirror each other through it (the fit's ``gait_symmetry`` term needs
  it and is skipped for a model without it);
- optionally ``lengthen(factor)``: start the bones along the body's longest axis ``factor`` times
  longer and hold them there (the template trials' longer body, ``trials.longer``; a model without
  it is fitted as it is, and the fit says so);
- optionally ``shared_displacement()``, a context manager within which the displacement field is
  evaluated once (the fit enters it around each loss evaluation, which poses the model and takes
  the symmetry and displacement terms with the same parameters).

`zooctl.rig.model.ArticulatedModel` implements all of it; a new model usually subclasses it and
replaces ``skinning`` (a function with `zooctl.rig.skinning.linear_blend_skinning`'s signature,
each output vertex a function of its own row alone: the model poses a seam's copies once and
gathers them), as `zooctl.rig.dqs.DualQuaternionModel` does.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

import torch

if TYPE_CHECKING:
    from ..asset import RiggedAsset
    from .model import Pose

Tensor = torch.Tensor


@runtime_checkable
class ArticulationModel(Protocol):
    points: Tensor
    faces: Tensor
    rest_rotation: Tensor

    @property
    def num_joints(self) -> int: ...

    def __call__(
        self,
        rotations: Tensor | None = None,
        root_rotation: Tensor | None = None,
        root_translation: Tensor | None = None,
    ) -> Pose: ...

    def global_scale(self) -> Tensor: ...

    def canonical_vertices(self) -> Tensor: ...

    def symmetry_loss(self, sample: int | None = 2000) -> Tensor: ...

    def bone_length_loss(self) -> Tensor: ...

    def smoothness_loss(self, rotations: Tensor) -> Tensor: ...


def get_articulation_model(
    name: str, asset: RiggedAsset, device: str = "cpu", **options: Any
) -> ArticulationModel:
    """Build the articulation model registered as ``name`` for ``asset``. Options its factory does
    not name (and it takes no ``**options``) are left out: a plugin written before an option
    existed ignores it instead of failing."""
    import inspect

    from ..plugins import get_registry

    spec = get_registry().get("articulation_model", name)
    try:
        params = inspect.signature(spec.factory).parameters.values()
    except (TypeError, ValueError):  # no signature to read (a builtin): pass everything
        params = None
    if params is not None and not any(p.kind is p.VAR_KEYWORD for p in params):
        named = {p.name for p in params}
        options = {k: v for k, v in options.items() if k in named}
    return spec.create(asset=asset, device=device, **options)
