"""The `clip` embedder plugin (plugins/zooctl-clip), pip-installed like a third-party package, loading
a small randomly initialised CLIP ViT checkpoint that the test writes to disk."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest
from cli_helpers import REPO, plugin_installed, zooctl

CLIP_PLUGIN = REPO / "plugins" / "zooctl-clip"


@pytest.fixture(scope="module")
def clip_installed():
    with plugin_installed(CLIP_PLUGIN, "zooctl-clip"):
        yield


@pytest.fixture(scope="module")
def checkpoint(clip_installed, tmp_path_factory):
    """A tiny CLIP (ViT width 64, 2 layers, patch 8, 32 px, 16-d) saved as OpenAI and OpenCLIP files."""
    import torch

    sys.path.insert(0, str(CLIP_PLUGIN))
    try:
        from zooctl_clip.model import VisionConfig, VisionTransformer
    finally:
        sys.path.pop(0)
    torch.manual_seed(0)
    model = VisionTransformer(VisionConfig(width=64, layers=2, heads=1, patch=8, grid=4, embed_dim=16))
    state = {f"visual.{k}": v for k, v in model.state_dict().items()}
    state["token_embedding.weight"] = torch.zeros(10, 8)  # the text tower is ignored
    d = tmp_path_factory.mktemp("clip")
    openai = d / "tiny-openai.pt"
    torch.save(state, openai)
    openclip = d / "tiny-openclip.pth"
    torch.save({"epoch": 1, "state_dict": {f"module.{k}": v for k, v in state.items()}}, openclip)
    broken = d / "broken.pt"
    torch.save({k: v for k, v in state.items() if "ln_post" not in k}, broken)
    return {"openai": openai, "openclip": openclip, "broken": broken}


_EMBED = textwrap.dedent(
    """
    import json, sys
    import numpy as np
    from zooctl.embed.base import get_embedder
    rng = np.random.default_rng(0)
    imgs = rng.integers(0, 256, (3, 50, 50, 3), dtype=np.uint8)
    e = get_embedder("clip")
    out = e.embed_batch(imgs)
    flipped = e.embed_batch(imgs[:, :, ::-1].copy())
    print(json.dumps({"dim": e.dim, "emb": out.tolist(), "flipped": flipped.tolist(), "identity": e.identity}))
    """
)


def _embed(weights) -> dict:
    r = zooctl_python(_EMBED, {"ZOOCTL_CLIP_WEIGHTS": str(weights)})
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def zooctl_python(code: str, env: dict) -> subprocess.CompletedProcess:
    import os

    return subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        env={**os.environ, **env},
        cwd=REPO,
        timeout=300,
    )


def test_clip_plugin_is_discovered(clip_installed):
    r = zooctl("plugins", "--json")
    assert r.code == 0, r.err
    clip = {p["name"]: p for p in r.json()["plugins"]}["clip"]
    assert clip["distribution"] == "zooctl-clip" and not clip["builtin"] and clip["status"] == "loaded"
    assert clip["registers"] == {"embedder": ["clip"]}


def test_checkpoint_loads_and_embeds(checkpoint):
    import numpy as np

    a = _embed(checkpoint["openai"])
    emb = np.array(a["emb"])
    assert a["dim"] == 16 and emb.shape == (3, 16)
    np.testing.assert_allclose(np.linalg.norm(emb, axis=1), 1, atol=1e-5)
    assert not np.allclose(emb, np.array(a["flipped"]), atol=1e-3)  # the image content matters
    b = _embed(checkpoint["openclip"])  # same weights in OpenCLIP's wrapping: same embeddings
    np.testing.assert_allclose(emb, np.array(b["emb"]), atol=1e-5)
    # The identity is the checkpoint file's digest: another file counts as another version (a
    # needless reindex at worst), so other weights of the same shape are never mixed with these.
    assert a["identity"].startswith("clip/") and a["identity"].endswith("/quick_gelu")
    assert a["identity"] != b["identity"] and a["identity"] == _embed(checkpoint["openai"])["identity"]
    info = zooctl("clip", "info", "--weights", str(checkpoint["openai"]))
    assert info.code == 0, info.err
    assert "width 64, 2 layers" in info.out and "patch 8, 32 px, embedding 16-d" in info.out


def test_bad_or_missing_checkpoint_is_one_clear_error(checkpoint, tmp_path):
    r = zooctl("clip", "info", "--weights", str(checkpoint["broken"]))
    assert r.code == 2 and "does not match a CLIP ViT" in r.err and "Traceback" not in r.err
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"not a checkpoint")
    code = textwrap.dedent(
        f"""
        from zooctl.embed.base import get_embedder
        from zooctl.errors import ZooctlError
        for w in ({str(tmp_path / "none.pt")!r}, {str(junk)!r}, None):
            try:
                get_embedder("clip", weights=w)
            except ZooctlError as exc:
                print(type(exc).__name__, exc.message, exc.hint)
        """
    )
    r = zooctl_python(code, {"ZOOCTL_CLIP_WEIGHTS": ""})
    lines = r.stdout.splitlines()
    assert len(lines) == 3, r.stderr
    assert lines[0].startswith("InputError") and "does not exist" in lines[0]
    assert lines[1].startswith("InputError") and "not a plain PyTorch checkpoint" in lines[1]
    assert lines[2].startswith("MissingDependencyError") and "ZOOCTL_CLIP_WEIGHTS" in lines[2]


def test_reindex_and_search_with_clip(checkpoint, tmp_path):
    """The plugin's embedder goes through the same store and search as the built-ins."""
    import numpy as np
    from PIL import Image

    store = tmp_path / "s"
    env = {"ZOOCTL_CLIP_WEIGHTS": str(checkpoint["openai"]), "ZOOCTL_VIEWS": "0"}
    code = textwrap.dedent(
        f"""
        from zooctl.procedural import build_animal
        from zooctl.store.bank import Bank
        b = Bank({str(store)!r})
        b.add(build_animal("fish", name="Fishy")); b.add(build_animal("spider", name="Leggy"))
        """
    )
    assert zooctl_python(code, env).returncode == 0
    r = zooctl(
        "bank",
        "reindex",
        "--embedder",
        "clip",
        "--embedder",
        "silhouette",
        "--views",
        "4",
        "--size",
        "64",
        store=store,
        env=env,
    )
    assert r.code == 0, r.err
    frames = tmp_path / "clip"
    frames.mkdir()
    for i in range(3):
        Image.fromarray(np.random.default_rng(i).integers(0, 256, (48, 64, 3), dtype=np.uint8)).save(
            frames / f"{i}.png"
        )
    r = zooctl("bank", "search", str(frames), "--embedder", "clip", "--json", store=store, env=env)
    assert r.code == 0, r.err
    out = r.json()
    assert out["embedders"] == ["clip"] and {m["name"] for m in out["matches"]} == {"Fishy", "Leggy"}
