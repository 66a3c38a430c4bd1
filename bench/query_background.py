"""Retrieval's query crops with the scene taken out, measured before it is built in (issue 50).

    .venv/bin/python bench/query_background.py -- bench run DIR --ablation retrieval-only --json

Runs the zooctl command after ``--`` with the embedders' query crops composited over a flat grey
(sRGB 128) through their masks, so the appearance embedding sees the animal's cut-out as the
bank's views show an animal over a plain background, not the video's scene. The classifier's
crops (`zooctl.retrieval.query.classifier_crops`) keep the photograph: the scene is context for
what the animal is. Crops without masks are left as they are. The retrieval code is not changed:
``crops_from_frames`` is wrapped in this process only.
"""

import sys

import numpy as np

import zooctl.retrieval.query as rq

GREY = 128
_crops = rq.crops_from_frames


def crops_from_frames(frames, masks, k, size):
    images, crop_masks, chosen = _crops(frames, masks, k, size)
    if crop_masks is not None:
        images = np.where(crop_masks[..., None], images, np.uint8(GREY))
    return images, crop_masks, chosen


rq.crops_from_frames = crops_from_frames

from zooctl.cli.main import run  # noqa: E402

sys.exit(run(sys.argv[sys.argv.index("--") + 1 :]))
