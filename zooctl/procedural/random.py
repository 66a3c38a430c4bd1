"""Random procedural animals: every body plan with proportions drawn from a plausible range.

`random_animal(rng, label)` builds one animal of a body-plan *label* (the labels retrieval is
judged on, `LABELS`), with each proportion drawn log-uniformly from the label's range in
`RANGES`. A label names the builder it uses (``"quadruped dinosaur"``: the quadruped builder with
a long neck, a long tail, a small head and a heavy body; ``"humanoid"``: the upright biped
builder; ``"biped dinosaur"``: the level dinosaur builder), and the animal records the label in
``meta["body_plan"]``. This is what `zooctl bank seed --random` adds and what
`zooctl embed train` learns from.
"""

from __future__ import annotations

import numpy as np

from ..asset import RiggedAsset
from ..errors import InputError
from .body import BodyParams

# Proportion ranges in metres, low-high ("-": the builder's default), per body-plan label and the
# builder it uses. The ranges reach cartoon proportions too (big heads, round bodies, short legs),
# as game assets have them.
_TABLE = """
label               builder    body_length leg_length neck_length tail_length head_size  girth      wing_length
quadruped           quadruped  0.7-1.3     0.3-0.85   0.12-0.7    0.08-0.6    0.13-0.26  0.13-0.27  -
quadruped_dinosaur  quadruped  1.0-1.6     0.35-0.7   0.5-1.4     0.9-1.8     0.09-0.16  0.24-0.36  -
biped_dinosaur      dinosaur   0.7-1.3     0.55-1.1   0.15-0.5    0.9-2.0     0.16-0.4   0.18-0.34  -
humanoid            biped      0.35-0.7    0.3-1.0    0.04-0.18   -           0.09-0.3   0.11-0.24  -
bird                bird       0.25-0.45   0.1-0.5    0.05-0.35   0.08-0.25   0.05-0.09  0.07-0.13  0.3-0.7
fish                fish       0.4-1.2     -          -           0.1-0.3     0.07-0.18  0.08-0.26  -
snake               snake      1.2-2.6     -          -           0.3-0.8     0.06-0.12  0.035-0.1  -
insect              insect     0.22-0.42   0.12-0.42  -           -           0.04-0.09  0.035-0.1  -
spider              spider     0.18-0.32   0.25-0.65  -           -           0.05-0.09  0.06-0.11  -
crab                crab       0.2-0.45    0.1-0.26   -           -           0.06-0.16  0.045-0.18 -
"""


def _parse(table: str) -> dict[str, tuple[str, dict[str, tuple[float, float]]]]:
    head, *rows = [line.split() for line in table.strip().splitlines()]
    out = {}
    for label, builder, *cells in rows:
        ranges = {
            k: tuple(float(x) for x in c.split("-")) for k, c in zip(head[2:], cells, strict=True) if c != "-"
        }
        out[label.replace("_", " ")] = (builder, ranges)
    return out


# label -> (builder plan, {proportion: (low, high)})
RANGES: dict[str, tuple[str, dict[str, tuple[float, float]]]] = _parse(_TABLE)
LABELS = tuple(RANGES)


def generator_identity() -> str:
    """A digest of the generator's source (every module of this package): training data made by
    another version of the generator is not reused."""
    import hashlib
    from pathlib import Path

    h = hashlib.sha256()
    for f in sorted(Path(__file__).parent.glob("*.py")):
        h.update(f.name.encode() + b"\0" + f.read_bytes())
    return h.hexdigest()[:16]


def random_params(rng: np.random.Generator, label: str) -> BodyParams:
    """Proportions of a ``label`` animal, each log-uniform in its range (zero stays possible)."""
    from . import PLANS

    if label not in RANGES:
        raise InputError(f"unknown body plan {label!r}", hint=f"plans: {', '.join(LABELS)}")
    plan, ranges = RANGES[label]
    p = PLANS[plan][0]
    vals = {}
    for k, (lo, hi) in ranges.items():
        vals[k] = (
            float(rng.uniform(lo, hi)) if lo <= 0 else float(np.exp(rng.uniform(np.log(lo), np.log(hi))))
        )
    return p.replace(**vals)


def random_animal(
    rng: np.random.Generator, label: str, name: str, seed: int = 0, any_hue: bool = False
) -> RiggedAsset:
    """One animal of body-plan ``label``: proportions from ``rng``, colours from ``seed`` and ``name``
    (around the plan's hue, or any hue with ``any_hue``)."""
    from . import build_animal

    params = random_params(rng, label)
    plan = RANGES[label][0]
    meta = {"body_plan": label, "tags": ["procedural", "random", label]}
    return build_animal(plan, params, seed=seed, name=name, meta=meta, any_hue=any_hue)


def random_assets(
    n: int, seed: int = 0, labels: list[str] | None = None, start: int = 0, any_hue: bool = False
) -> list[RiggedAsset]:
    """``n`` random animals cycling through ``labels`` (default: all), named
    ``random-<plan>-<seed>-<i>`` for i from ``start``; the same seed and i give the same animal."""
    labels = list(labels or LABELS)
    for lab in labels:
        if lab not in RANGES:
            raise InputError(f"unknown body plan {lab!r}", hint=f"plans: {', '.join(LABELS)}")
    out = []
    for i in range(start, start + n):
        label = labels[i % len(labels)]
        rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, i])
        name = f"random-{label.replace(' ', '-')}-{seed}-{i:04d}"
        out.append(random_animal(rng, label, name, seed, any_hue))
    return out
