"""Built-in video components: segmenters (`masks`, `grabcut`, `selftrain`, `animalnet`, `onnx`) and the `dis`
flow estimator.

Factories import their modules lazily so that `zooctl --help` does not pay for OpenCV.
"""

from __future__ import annotations

from ..components import ComponentSpec
from ..plugins import hookimpl


def _masks(**options):
    from ..video.segment import MaskSegmenter

    return MaskSegmenter(**options)


def _grabcut(**options):
    from ..video.grabcut import GrabCutTracker

    return GrabCutTracker(**options)


def _selftrain(**options):
    from ..video.selftrain import SelfTrainedSegmenter

    return SelfTrainedSegmenter(**options)


def _animalnet(**options):
    from ..video.animalnet import AnimalNetSegmenter

    return AnimalNetSegmenter(**options)


def _onnx(**options):
    from ..video.segment import OnnxSegmenter

    return OnnxSegmenter(**options)


def _dis(**options):
    from ..video.flow import DISFlow

    return DISFlow(**options)


@hookimpl
def register_segmenters(register):
    register(
        ComponentSpec(
            "segmenter", "masks", _masks, "your own masks: a folder of mask images or a mask video (--masks)"
        )
    )
    register(
        ComponentSpec(
            "segmenter",
            "grabcut",
            _grabcut,
            "classical, CPU: seeded by --box (any frame) or by the animal localiser (ImageNet class maps + motion), "
            "motion + colour cues, GrabCut tracked both ways along the flow, re-seeded when the localiser disagrees",
        )
    )
    register(
        ComponentSpec(
            "segmenter",
            "selftrain",
            _selftrain,
            "grabcut, then a classifier learned from this video's sure pixels (EfficientNet-Lite0 features + "
            "colour) decides every frame again (a leak or a dropped part on some frames is repaired); CPU, no weights",
        )
    )
    register(
        ComponentSpec(
            "segmenter",
            "animalnet",
            _animalnet,
            "the default: grabcut, checked by a network trained on synthetic animals (EfficientNet-Lite0 features + "
            "motion; replaces a tracker lost on the background), then relabelled per video as selftrain; CPU, "
            "shipped weights (procedural animals only), the store's from `zooctl segment train`, or weights=PATH",
        )
    )
    register(
        ComponentSpec(
            "segmenter",
            "onnx",
            _onnx,
            "a segmentation network from a local .onnx file (--model PATH); box/point prompts if it takes them",
        )
    )


@hookimpl
def register_flow_estimators(register):
    register(
        ComponentSpec("flow_estimator", "dis", _dis, "OpenCV DIS optical flow (preset ultrafast|fast|medium)")
    )
