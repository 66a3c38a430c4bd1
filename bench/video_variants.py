"""The automatic masks of the shared DAVIS videos, and of the same videos changed in ways that
should not matter: is a J measured on them what an unseen video gets?

    ZOOCTL_STORE=S python bench/video_variants.py [--variants jpeg h264 mirror] [--work DIR]
        [--add-option=--seg-option --add-option=K=V] [--json OUT]

Each of the seven DAVIS videos is stored by `zooctl video add` (no box, every default) as given
(``jpeg``: its JPEG folder), encoded as a phone would (``h264``: H.264 at CRF 23, yuv420p, 24
frames/s, by the ffmpeg of imageio-ffmpeg) and mirrored left to right (``mirror``: a JPEG folder
at quality 95, the truth mirrored too). The animal, the camera's motion and the scene are the same
in all three; the masks should be too. J per video is the mean over frames of each frame's J
against the truth. Stored as ``VARIANT-VIDEO`` (replaced if there); the variants' files are made
in ``--work`` (default: a temporary folder).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
from _util import SHARED

from zooctl.fit.inputs import _read_mask_folder
from zooctl.paths import default_store
from zooctl.store.videos import VideoStore
from zooctl.video.mask_quality import per_frame_j

DAVIS = SHARED / "videos"
VARIANTS = ("jpeg", "h264", "mirror")


def variant_source(variant: str, video: str, work: Path) -> Path:
    """The file or folder `video add` reads for ``variant`` of DAVIS ``video`` (made in ``work``)."""
    src = DAVIS / video / "JPEGImages"
    if variant == "jpeg":
        return src
    if variant == "h264":
        import imageio_ffmpeg

        out = work / f"{video}.mp4"
        cmd = [imageio_ffmpeg.get_ffmpeg_exe(), "-loglevel", "error", "-y", "-framerate", "24"]
        cmd += ["-i", str(src / "%05d.jpg"), "-c:v", "libx264", "-crf", "23", "-pix_fmt", "yuv420p", str(out)]
        subprocess.run(cmd, check=True)
        return out
    out = work / "mirror" / video
    out.mkdir(parents=True, exist_ok=True)
    for f in sorted(src.glob("*.jpg")):
        cv2.imwrite(str(out / f.name), cv2.imread(str(f))[:, ::-1], [cv2.IMWRITE_JPEG_QUALITY, 95])
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--variants", nargs="+", choices=VARIANTS, default=list(VARIANTS))
    ap.add_argument("--work", type=Path)
    ap.add_argument("--add-option", action="append", default=[])
    ap.add_argument("--json", type=Path)
    args = ap.parse_args()
    if not DAVIS.is_dir():
        sys.exit(f"skipped: the shared DAVIS videos are not at {DAVIS}")
    videos = sorted(p.name for p in DAVIS.iterdir() if (p / "Annotations").is_dir())
    store = VideoStore(default_store())
    rows: dict[str, dict[str, float]] = {v: {} for v in videos}
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        for video in videos:
            for variant in args.variants:
                name = f"{variant}-{video}"
                t0 = time.perf_counter()
                cmd = [
                    sys.executable,
                    "-m",
                    "zooctl",
                    "video",
                    "add",
                    str(variant_source(variant, video, work)),
                ]
                cmd += ["--name", name, "-q", "--replace", *args.add_option]
                subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
                rec = store.get(name, what=("masks",))
                truth = _read_mask_folder(
                    DAVIS / video / "Annotations", rec.source_indices, rec.masks.shape[1:]
                )
                if variant == "mirror":
                    truth = truth[:, :, ::-1]
                rows[video][variant] = float(np.mean(per_frame_j(rec.masks, truth)))
                print(
                    f"{video:14s} {variant:6s} J {rows[video][variant]:.3f} ({time.perf_counter() - t0:.1f} s)"
                )
    print("\n| video | " + " | ".join(args.variants) + " | spread |")
    print("|---|" + "---:|" * (len(args.variants) + 1))
    for video, r in rows.items():
        js = [r[v] for v in args.variants]
        print(f"| {video} | " + " | ".join(f"{j:.3f}" for j in js) + f" | {max(js) - min(js):.3f} |")
    means = [float(np.mean([rows[v][x] for v in videos])) for x in args.variants]
    worst = float(np.mean([min(rows[v].values()) for v in videos]))
    print(
        "| **mean** | "
        + " | ".join(f"**{m:.3f}**" for m in means)
        + f" | worst variant a video: {worst:.3f} |"
    )
    if args.json:
        args.json.write_text(json.dumps({"variants": args.variants, "videos": rows}, indent=1))


if __name__ == "__main__":
    main()
