"""Built-in motion priors: ``ponymation`` (spatio-temporal transformer VAE over bone tokens) and
``pca`` (the per-skeleton Gaussian/PCA baseline)."""

from __future__ import annotations

from typing import Any

from ..components import ComponentSpec
from ..plugins import hookimpl


def _ponymation(path: Any = None, device: str = "cpu", **options: Any) -> Any:
    from ..motion.prior import PonymationPrior

    if path is not None:
        return PonymationPrior.load(path, device=device)
    return PonymationPrior(device=device, **options)


def _pca(path: Any = None, device: str = "cpu", **options: Any) -> Any:
    from ..motion.pca_prior import PCAPrior

    if path is not None:
        return PCAPrior.load(path, device=device)
    return PCAPrior(device=device, **options)


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
    register(
        ComponentSpec(
            "motion_prior",
            "pca",
            _pca,
            "per-skeleton Gaussian over principal components of 6D rotation windows (the baseline)",
        )
    )
