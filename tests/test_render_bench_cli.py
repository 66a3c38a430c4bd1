"""`zooctl bench render|rig` and the renderer plugins, through the real CLI."""

import pytest
import torch
from cli_helpers import zooctl

from zooctl.plugins import get_registry
from zooctl.render.camera import look_at
from zooctl.rig.synthetic import uv_sphere


def test_bench_render_json():
    renderer = "flow"
    res = zooctl(
        "bench",
        "render",
        "--renderer",
        renderer,
        "--faces",
        "200",
        "--size",
        "32",
        "--batch",
        "2",
        "--repeats",
        "1",
        "--json",
    )
    assert res.code == 0, res.err
    out = res.json()
    assert out["renderer"] == renderer and out["batch"] == 2 and out["ms_per_frame"] > 0


@pytest.mark.parametrize("renderer", ["soft", "fast"])
def test_bench_render_in_process(renderer):
    from zooctl.render.benchmark import bench_render

    out = bench_render(renderer, faces=200, size=32, batch=2, repeats=1)
    assert out["renderer"] == renderer and out["ms_per_frame"] > 0


def test_bench_rig_and_bad_options():
    res = zooctl(
        "bench", "rig", "--vertices", "300", "--joints", "5", "--frames", "2", "--repeats", "1", "--json"
    )
    assert res.code == 0, res.err
    assert res.json()["joints"] == 5
    bad = zooctl("bench", "render", "--renderer", "nope")
    assert bad.code == 2 and "no renderer named" in bad.err and "Traceback" not in bad.err
    if not torch.cuda.is_available():
        nocuda = zooctl("bench", "render", "--device", "cuda")
        assert nocuda.code == 2 and "CUDA" in nocuda.err


def test_registered_renderers_render():
    reg = get_registry()
    v, f = uv_sphere(200)
    verts, faces = torch.as_tensor(v)[None], torch.as_tensor(f)
    cam = look_at([0.0, 0.0, 4.0], [0.0, 0.0, 0.0], 24, 24)
    for name in ("soft", "fast"):
        sil = reg.get("renderer", name).create(image_size=24)(verts, faces, cam)
        assert sil.shape == (1, 24, 24) and sil.max() > 0.9
    out = reg.get("renderer", "flow").create(image_size=24)(verts, faces, cam, verts + 0.1)
    assert out["flow"].shape == (1, 24, 24, 2) and out["mask"].any()
