"""Built-in video components: segmenters (`masks`, `grabcut`, `selftrain`, `animalnet`, `onnx`) and the `dis`
flow estimator.

Factories import their modules lazily so that `zooctl --help` does not pay for OpenCV.
"""

from __future__ import annotations

from ..components import ComponentSpec
from ..plugins import hookimpl


def _typed(options: dict, *classes) -> dict:
    """``options`` as given, once every option that one of ``classes`` takes with a number or
    true/false default holds a value of that kind (a segmenter forwards the options it does not
    take to its tracker: both classes are given); else one clear UsageError, not a TypeError deep
    inside the segmentation."""
    import inspect

    from ..errors import UsageError

    for cls in classes:
        for name, p in inspect.signature(cls.__init__).parameters.items():
            if name not in options or p.default is inspect.Parameter.empty or p.default is None:
                continue
            v, d = options[name], p.default
            if isinstance(d, bool):
                if not isinstance(v, bool):
                    raise UsageError(
                        f"segmenter option {name}={v!r} is not true or false",
                        hint=f"e.g. {name}={str(d).lower()}",
                    )
            elif isinstance(d, int) and (isinstance(v, bool) or not isinstance(v, int)):
                raise UsageError(
                    f"segmenter option {name}={v!r} is not a whole number", hint=f"e.g. {name}={d}"
                )
            elif isinstance(d, float) and (isinstance(v, bool) or not isinstance(v, (int, float))):
                raise UsageError(f"segmenter option {name}={v!r} is not a number", hint=f"e.g. {name}={d}")
    return options


def _masks(**options):
    from ..video.segment import MaskSegmenter

    return MaskSegmenter(**options)


def _grabcut(**options):
    from ..video.grabcut import GrabCutTracker

    return GrabCutTracker(**_typed(options, GrabCutTracker))


def _selftrain(**options):
    from ..video.grabcut import GrabCutTracker
    from ..video.selftrain import SelfTrainedSegmenter

    return SelfTrainedSegmenter(**_typed(options, SelfTrainedSegmenter, GrabCutTracker))


def _animalnet(**options):
    from ..video.animalnet import AnimalNetSegmenter
    from ..video.grabcut import GrabCutTracker

    return AnimalNetSegmenter(**_typed(options, AnimalNetSegmenter, GrabCutTracker))


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
