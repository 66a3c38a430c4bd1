"""The temperature a prior samples at unless told otherwise (no torch: `zooctl motion list`
reads it from config.json files)."""

from __future__ import annotations

from typing import Any


def draws_diversely(model: dict[str, Any]) -> bool:
    """Whether a prior of this ``model`` config (config.json ``model``) draws a call's windows
    together, spread over the skeleton's latents (`MotionConfig.diverse`)."""
    return model.get("sampler", "mixture") == "mixture" and bool(model.get("diverse", True))


def default_temperature(model: dict[str, Any], training: dict[str, Any]) -> float:
    """The temperature samples use unless told otherwise, from a prior's config.json ``model`` and
    ``training``: 1 when it draws diversely (each window's own posterior: the spread between
    the windows gives the variety, BENCHMARKS.md); else the one calibrated at training on the
    training windows' diversity (`zooctl.motion.calibrate`), 1 for priors older than that."""
    if draws_diversely(model):
        return 1.0
    return float(training.get("sample_temperature", 1.0))
