"""The colour snap's gate chosen leave-one-video-out, and the masks' J with and without it.

    ZOOCTL_STORE=S python bench/colour_snap.py [--davis OFF ALWAYS] [--bench DIR OFF ALWAYS]...
        [--json OUT]

Each video is stored twice by `zooctl video add`: as ``OFF-name`` with ``--seg-option snap=false``
(the masks before the snap) and as ``ALWAYS-name`` with ``--seg-option snap_gain=-1`` (every video
snapped; its report holds the separation gain that the gate reads). A video keeps the snapped masks
when its gain exceeds the threshold, as `zooctl.video.colour_snap.snap_video` decides. The sets,
J and the leave-one-video-out choice of the threshold: `_mask_gate`.
"""

from __future__ import annotations

import _mask_gate
import numpy as np

GRID = [float(x) for x in np.round(np.arange(-0.05, 0.21, 0.005), 3)]


def gain(seeding: dict) -> float | None:
    return (seeding.get("colour_snap") or {}).get("separation_gain")


if __name__ == "__main__":
    _mask_gate.main(__doc__, gain, GRID, "gain", "snapped")
