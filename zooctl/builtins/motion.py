"""Built-in motion prior: ``ponymation`` (spatio-temporal transformer VAE over bone tokens)."""

from __future__ import annotations

from typing import Any

from ..components import ComponentSpec
from ..plugins import hookimpl


def _ponymation(path: Any = None, device: str = "cpu", **options: Any) -> Any:
    from ..motion.prior import PonymationPrior

    if path is not None:
        return PonymationPrior.load(path, device=device)
    return PonymationPrior(device=device, **options)


@hookimpl
def register_motion_priors(register):
    register(
        ComponentSpec(
            "motion_prior",
            "ponymation",
            _ponymation,
            "Ponymation-style transformer VAE over per-bone 6D rotations, any skeleton (bone tokens + masks)",
        )
    )
