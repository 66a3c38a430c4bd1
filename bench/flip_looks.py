"""The segmenter's looks at each frame and its mirror image (`--seg-option flip=true`): on or off,
chosen leave-one-video-out, and the masks' J either way.

    for d in DIR/*/; do n=$(basename $d | tr A-Z a-z)
        zooctl video add $d --name off-$n; zooctl video add $d --name on-$n --seg-option flip=true; done
    ZOOCTL_STORE=S python bench/flip_looks.py --bench DIR off on [--bench DIR2 off on] [--davis off on]

The switch is `_mask_gate`'s gate with a number every video has (1): threshold 0 turns it on
for every video, infinity off, so the on/off choice is made as the gates' thresholds are (the
largest mean J gain, each set weighing alike, no set falling), on all videos and
leave-one-video-out. The DAVIS videos in their three variants (as given, H.264, mirrored) come
from `bench/video_variants.py`, run once per setting; ``--variants OFF.json ON.json`` prints
their table, on or off chosen leave-one-video-out with a video's three variants left out together.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))


def variants(off: Path, on: Path) -> None:
    """The DAVIS variants' table from two `video_variants.py --json` files."""

    def j_of(path: Path) -> dict[tuple[str, str], float]:
        rows = json.loads(path.read_text())["videos"]
        return {(v, k): float(j) for v, r in rows.items() for k, j in r.items()}

    a, b = j_of(off), j_of(on)
    videos = sorted({v for v, _ in a})
    kinds = sorted({k for _, k in a}, key=["jpeg", "h264", "mirror"].index)

    def gain(vs) -> list[float]:  # per variant set, mean gain of turning it on over these videos
        return [float(np.mean([b[v, k] - a[v, k] for v in vs])) for k in kinds]

    def on_for(vs) -> bool:
        g = gain(vs)
        return min(g) >= 0 and float(np.mean(g)) > 0

    loo = {v: on_for([u for u in videos if u != v]) for v in videos}
    print(f"on, chosen on all {len(videos)} videos: {on_for(videos)}")
    print("| masks' J | " + " | ".join(kinds) + " | the worst of a video's variants |")
    print("|---|" + "---:|" * (len(kinds) + 1))
    for label, pick in (
        ("off", lambda v: a),
        ("on", lambda v: b),
        ("leave-one-out", lambda v: b if loo[v] else a),
    ):
        cells = [np.mean([pick(v)[v, k] for v in videos]) for k in kinds]
        worst = np.mean([min(pick(v)[v, k] for k in kinds) for v in videos])
        print(f"| {label} | " + " | ".join(f"{c:.3f}" for c in cells) + f" | {worst:.3f} |")
    for v in videos:
        print(
            f"  {v:14s} "
            + "  ".join(f"{k} {a[v, k]:.3f} -> {b[v, k]:.3f}" for k in kinds)
            + f"  (left out: {'on' if loo[v] else 'off'})"
        )


if __name__ == "__main__":
    if "--variants" in sys.argv:
        ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
        ap.add_argument("--variants", nargs=2, type=Path, metavar=("OFF", "ON"), required=True)
        variants(*ap.parse_args().variants)
    else:
        import _mask_gate

        _mask_gate.main(__doc__, lambda seeding: 1.0, [0.0, float(np.inf)], "flip", "flip on")
