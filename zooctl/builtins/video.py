"""Built-in video components: segmenters (`masks`, `grabcut`, `onnx`) and the `dis` flow estimator.

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
            "classical, CPU: first-frame box (--box, else the moving object), motion + colour cues, GrabCut tracked along the flow",
        )
    )
    register(
        ComponentSpec(
            "segmenter",
            "onnx",
            _onnx,
            "a salient-object/matting network from a local .onnx file (--model PATH)",
        )
    )


@hookimpl
def register_flow_estimators(register):
    register(
        ComponentSpec("flow_estimator", "dis", _dis, "OpenCV DIS optical flow (preset ultrafast|fast|medium)")
    )
