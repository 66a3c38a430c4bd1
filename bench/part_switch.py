"""The network's part of the tracked animal in place of a tracker that holds only a piece of it:
its gate chosen leave-one-video-out, and the masks' J with and without it.

    ZOOCTL_STORE=S python bench/part_switch.py [--davis KEPT OPEN] [--bench DIR KEPT OPEN]...
        [--json OUT]

``KEPT-name`` is stored by `zooctl video add` with ``--seg-option switch_cover=-1`` (the tracker's
masks stand), ``OPEN-name`` with ``--seg-option switch_cover=0`` (the network's part replaces them
whenever it holds the tracked region). The gate reads ``part_cover``: how many times the tracked
area the network's part covers (`zooctl.video.animalnet.part_cover`). The rest: `_mask_gate`.
"""

from __future__ import annotations

import _mask_gate
import numpy as np

GRID = [float(x) for x in np.round(np.exp(np.linspace(0.0, np.log(20.0), 41)), 2)] + [float(np.inf)]


def cover(seeding: dict) -> float | None:
    return (seeding.get("animalnet") or {}).get("part_cover")


if __name__ == "__main__":
    _mask_gate.main(__doc__, cover, GRID, "cover", "replaced")
