"""C++ CPU kernels of the renderers against their pure-PyTorch paths (same outputs, same gradients).

Every renderer has two implementations selected automatically (`zooctl.render._kernels`): these
tests run both on the same inputs, check that they agree (1e-5 on images, float32 gradients to
a small fraction of their scale, float64 to 1e-9), gradcheck the kernels' hand-written backward
passes in float64, and check the automatic fallback when no compiler is available.
"""

import contextlib
import os
import subprocess
import sys

import pytest
import torch

from zooctl.render import _kernels
from zooctl.render.camera import look_at
from zooctl.render.raster import RasterFlow, interpolate, rasterize
from zooctl.render.soft import SoftSilhouette, _SoftSilhouetteKernel
from zooctl.render.splat import SplatSilhouette, _SplatSilhouetteKernel, subdivision_barycentrics
from zooctl.render.windows import face_windows, project_faces
from zooctl.rig.synthetic import uv_sphere

pytestmark = [
    pytest.mark.usefixtures("one_thread"),
    pytest.mark.skipif(
        not _kernels.available(), reason=f"renderer kernels did not build: {_kernels.error()}"
    ),
]


def _scene(dtype, faces=500, size=(40, 48), batch=2):
    """A sphere in two poses seen by two cameras; the second pose pokes out of the image."""
    v, f = uv_sphere(faces)
    v = torch.as_tensor(v, dtype=dtype)
    verts = torch.stack(
        (v * torch.tensor([1.2, 0.8, 1.0], dtype=dtype), v + torch.tensor([0.9, -0.7, 0.3], dtype=dtype))
    )
    verts = verts[:batch].clone().requires_grad_(True)
    eyes = [[0.0, 0.3, 3.5], [1.5, 1.0, 2.5]][:batch]
    cam = look_at(eyes, [0.1, 0.0, 0.0], size[0], size[1], dtype=dtype)
    return verts, torch.as_tensor(f), cam


def _both(fn, verts):
    """fn() -> tensor, run with kernels and with the PyTorch path: (out, grad) for each."""
    results = []
    for use_kernels in (True, False):
        verts.grad = None
        g = torch.Generator().manual_seed(1)
        if use_kernels:
            out = fn()
        else:
            with _kernels.disabled():
                out = fn()
        w = torch.rand(out.shape, generator=g, dtype=out.dtype)
        (out * w).sum().backward()
        results.append((out.detach(), verts.grad.clone()))
    return results


def _assert_grads_close(ga, gb, dtype):
    scale = gb.abs().max()
    assert scale > 0
    rel = 2e-4 if dtype == torch.float32 else 1e-9
    assert (ga - gb).abs().max() <= rel * scale


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("sigma", [0.05, 0.5, 3.0])
def test_soft_kernel_matches_pytorch(dtype, sigma):
    verts, faces, cam = _scene(dtype)
    render = SoftSilhouette((40, 48), sigma=sigma)
    (a, ga), (b, gb) = _both(lambda: render(verts, faces, cam), verts)
    assert (a - b).abs().max() <= 1e-5
    _assert_grads_close(ga, gb, dtype)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize(
    "options", [{}, {"samples": 2, "blur": 0.0}, {"samples": 1, "blur": 1.5, "gain": 3.0}]
)
def test_fast_kernel_matches_pytorch(dtype, options):
    verts, faces, cam = _scene(dtype)
    render = SplatSilhouette((40, 48), **options)
    (a, ga), (b, gb) = _both(lambda: render(verts, faces, cam), verts)
    assert (a - b).abs().max() <= 1e-5
    _assert_grads_close(ga, gb, dtype)


def test_fast_handles_samples_clamped_below_the_last_image():
    """A face far below the image in the last batch element (the splat's spare padding row)."""
    v = torch.tensor([[[-0.5, -3.0, 0.0], [0.5, -3.0, 0.0], [0.0, -2.0, 0.0], [0.0, 0.0, 0.0]]] * 2)
    v[1, :3, 0] += 4.0  # and one past the right edge
    f = torch.tensor([[0, 1, 2]])
    cam = look_at([0.0, 0.0, 3.0], [0.0, 0.0, 0.0], 16, 16)
    v.requires_grad_(True)
    (a, ga), (b, gb) = _both(lambda: SplatSilhouette(16, samples=2)(v, f, cam), v)
    assert torch.equal(a, b) and a.max() < 1e-3


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_raster_and_flow_kernels_match_pytorch(dtype):
    verts, faces, cam = _scene(dtype, faces=800)
    cam.intrinsics.requires_grad_(True)  # the fit optimises the focal length
    moved = (
        verts.detach() @ torch.tensor([[0.99, -0.1, 0.0], [0.1, 0.99, 0.0], [0.0, 0.0, 1.0]], dtype=dtype).T
        + 0.05
    )

    outs = {}
    for use_kernels in (True, False):
        verts.grad, cam.intrinsics.grad = None, None
        ctx = _kernels.disabled() if not use_kernels else torch.enable_grad()
        with ctx:
            out = RasterFlow()(verts, faces, cam, moved + (verts - verts.detach()))
            pos = interpolate(verts, faces, rasterize(verts, faces, cam))
        (out["flow"].square().sum() + out["depth"].sum() + out["bary"].sum() + pos.sum()).backward()
        outs[use_kernels] = (out, pos.detach(), verts.grad.clone(), cam.intrinsics.grad.clone())
    (ka, pa, ga, ia), (kb, pb, gb, ib) = outs[True], outs[False]
    assert torch.equal(ka["face_ids"], kb["face_ids"]) and torch.equal(ka["mask"], kb["mask"])
    assert ka["mask"].sum() > 500
    for key in ("flow", "depth", "bary"):
        assert (ka[key] - kb[key]).abs().max() <= 1e-5 * max(1.0, float(kb[key].detach().abs().max()))
    assert (pa - pb).abs().max() <= 1e-5
    _assert_grads_close(ga, gb, dtype)
    _assert_grads_close(ia, ib, dtype)


def test_results_do_not_depend_on_the_thread_count():
    verts, faces, cam = _scene(torch.float32, batch=1)  # one image: split into row bands
    runs = []
    for threads in (1, 2, 3):
        torch.set_num_threads(threads)
        verts.grad = None
        sil = SoftSilhouette((40, 48))(verts, faces, cam)
        flow = RasterFlow()(verts, faces, cam, verts + 0.1)["flow"]
        (sil.sum() + flow.sum()).backward()
        runs.append((sil.detach(), flow.detach(), verts.grad.clone()))
    for other in runs[1:]:
        assert all(torch.equal(x, y) for x, y in zip(runs[0], other))


def _random_triangles(n, size, seed):
    g = torch.Generator().manual_seed(seed)
    centre = torch.rand(n, 1, 2, generator=g, dtype=torch.float64) * size
    return centre + (torch.rand(n, 3, 2, generator=g, dtype=torch.float64) - 0.5) * 6


def test_soft_kernel_gradcheck():
    tri = _random_triangles(6, 10, seed=0).requires_grad_(True)  # 2 images x 3 faces, 10 x 12 px
    sf = type("SF", (), {})()
    sf.tri, sf.valid, sf.num_faces = tri.detach(), torch.ones(6, dtype=torch.bool), 3
    win = face_windows(sf, 10, 12, 3.0).to(torch.int32).contiguous()
    assert torch.autograd.gradcheck(lambda t: _SoftSilhouetteKernel.apply(t, win, 2, 10, 12, 1.5), (tri,))


def test_fast_kernel_gradcheck():
    tri = _random_triangles(4, 8, seed=1).requires_grad_(True)
    bary = subdivision_barycentrics(2, torch.float64)
    valid = torch.tensor([1.0, 1.0, 0.0, 1.0], dtype=torch.float64)
    k = torch.tensor([0.25, 0.5, 0.25], dtype=torch.float64)
    assert torch.autograd.gradcheck(
        lambda t: _SplatSilhouetteKernel.apply(t, bary, valid, k, 2.0, 2, 9, 10), (tri,)
    )


def test_raster_kernels_gradcheck():
    verts, faces, cam = _scene(torch.float64, faces=40, size=(12, 14), batch=1)
    cam.intrinsics.requires_grad_(True)
    moved = verts.detach() + torch.tensor([0.05, 0.02, -0.03], dtype=torch.float64)

    def fn(v, k):
        c = type(cam)(k, cam.rotation, cam.translation, cam.height, cam.width)
        out = RasterFlow()(v, faces, c, moved + v)
        return out["flow"], out["depth"], out["bary"]

    assert torch.autograd.gradcheck(fn, (verts, cam.intrinsics))


def test_kernels_apply_only_to_cpu_float_tensors():
    x = torch.zeros(3, 2)
    assert _kernels.kernel_for("soft_forward", x) is not None
    assert _kernels.kernel_for("soft_forward", x.half()) is None
    assert _kernels.kernel_for("soft_forward", x, x.double()) is None
    assert _kernels.kernel_for("soft_forward", x.to("meta")) is None  # CUDA takes the PyTorch path alike
    assert _kernels.kernel_for("zbuffer", x, indices=(torch.zeros(2, dtype=torch.int32),)) is None
    with _kernels.disabled():
        assert _kernels.kernel_for("soft_forward", x) is None
    with pytest.raises(ValueError, match="contiguous"):
        _kernels.kernel_for("soft_forward", x)(x.t(), x, 1, 1, 1, 1, 1.0, x)


def test_falls_back_to_pytorch_without_a_compiler(tmp_path):
    """No compiler: one warning, the PyTorch path, the same images (fresh process, empty cache)."""
    code = (
        "import warnings, torch\n"
        "from zooctl.render import _kernels\n"
        "from zooctl.render.soft import SoftSilhouette\n"
        "from zooctl.render.camera import look_at\n"
        "from zooctl.rig.synthetic import uv_sphere\n"
        "v, f = uv_sphere(100)\n"
        "cam = look_at([0.0, 0.0, 4.0], [0.0, 0.0, 0.0], 16, 16)\n"
        "with warnings.catch_warnings(record=True) as w:\n"
        "    warnings.simplefilter('always')\n"
        "    sil = SoftSilhouette(16)(torch.as_tensor(v)[None], torch.as_tensor(f), cam)\n"
        "assert not _kernels.available() and 'compiler' in _kernels.error()\n"
        "assert sum('PyTorch path' in str(x.message) for x in w) == 1\n"
        "print(float(sil.sum()))\n"
    )
    env = dict(os.environ, CXX=str(tmp_path / "no-such-compiler"), TORCH_EXTENSIONS_DIR=str(tmp_path))
    env.pop("ZOOCTL_RENDER_KERNELS", None)
    res = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stderr
    v, f = uv_sphere(100)
    cam = look_at([0.0, 0.0, 4.0], [0.0, 0.0, 0.0], 16, 16)
    expected = float(SoftSilhouette(16)(torch.as_tensor(v)[None], torch.as_tensor(f), cam).sum())
    assert abs(float(res.stdout.strip()) - expected) < 1e-3


def test_environment_switch_disables_kernels(monkeypatch):
    monkeypatch.setenv("ZOOCTL_RENDER_KERNELS", "0")
    assert not _kernels.enabled() and _kernels.kernel_for("soft_forward", torch.zeros(1)) is None


def test_build_is_cached_and_keyed_by_the_sources(tmp_path, monkeypatch):
    lib = _kernels.build()  # built already (this module's skip condition): found, not rebuilt
    assert lib.parent == _kernels.cache_dir() and lib.exists()
    inode = lib.stat().st_ino  # a rebuild renames a new file over it; a use only touches it
    assert _kernels.build() == lib and lib.stat().st_ino == inode
    cxx = _kernels._compiler()
    before = _kernels._build_hash(cxx)
    for src in _kernels.SOURCE_DIR.iterdir():
        if src.suffix in (".cpp", ".h"):
            (tmp_path / src.name).write_bytes(src.read_bytes())
    monkeypatch.setattr(_kernels, "SOURCE_DIR", tmp_path)
    assert _kernels._build_hash(cxx) == before
    with open(tmp_path / "soft.cpp", "a") as fh:
        fh.write("// edited\n")
    assert _kernels._build_hash(cxx) != before  # an edited source gets a new library


def test_project_faces_kernel_marks_invalid_faces():
    v = torch.tensor(
        [[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 5.0], [float("nan"), 0.0, 0.0]]]
    )
    f = torch.tensor([[0, 1, 2], [0, 1, 3], [0, 1, 4]])  # fine, behind the camera, NaN
    cam = look_at([0.0, 0.0, 3.0], [0.0, 0.0, 0.0], 16, 16)
    a = project_faces(v, f, cam)
    with _kernels.disabled():
        b = project_faces(v, f, cam)
    assert a.valid.tolist() == b.valid.tolist() == [True, False, False]
    assert torch.equal(a.tri[:2], b.tri[:2]) and torch.equal(a.depth[:2], b.depth[:2])


def test_bad_face_indices_are_an_input_error_not_a_memory_error():
    from zooctl.errors import InputError

    v, f = uv_sphere(100)
    verts, faces = torch.as_tensor(v)[None], torch.as_tensor(f)
    cam = look_at([0.0, 0.0, 4.0], [0.0, 0.0, 0.0], 16, 16)
    bad = faces.clone()
    bad[3, 1] = verts.shape[1]
    for render in (SoftSilhouette(16), SplatSilhouette(16), lambda v, f, c: RasterFlow()(v, f, c, v)):
        with pytest.raises(InputError, match="faces index vertices"):
            render(verts, bad, cam)
    with pytest.raises(InputError, match="faces must be"):
        SoftSilhouette(16)(verts, faces[:, :2], cam)


def test_prune_deletes_only_stale_other_builds(tmp_path):
    import os
    import time

    old, recent, keep = (tmp_path / f"render-{n}.so" for n in ("old", "recent", "keep"))
    for p in (old, recent, keep):
        p.write_bytes(b"x")
    month_ago = time.time() - 40 * 86400
    os.utime(old, (month_ago, month_ago))
    os.utime(keep, (month_ago, month_ago))  # the library in use is never deleted
    (tmp_path / "other.txt").write_bytes(b"x")
    os.utime(tmp_path / "other.txt", (month_ago, month_ago))
    assert _kernels.prune(tmp_path, keep=keep) == [old]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["other.txt", "render-keep.so", "render-recent.so"]


def test_soft_backward_leaves_the_callers_denormals_alone():
    """The backward flushes denormals on its own threads only: afterwards this thread's float
    arithmetic still keeps them (a leaked flush mode would change every later computation)."""
    verts, faces, cam = _scene(torch.float32, batch=1)
    tiny = torch.tensor([1e-39])  # below float's normal range
    assert tiny.item() != 0.0
    SoftSilhouette((40, 48), sigma=0.05)(verts, faces, cam).sum().backward()
    assert (tiny * 1.0).item() != 0.0 and (tiny / 2).item() != 0.0


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_edge_length_kernel_matches_pytorch(dtype):
    """The edge-stretch term's squared lengths and gradients, a zero-length edge (clamped) included."""
    from zooctl.fit.losses import edge_squared_length, edge_stretch_loss, mesh_edges

    v, f = uv_sphere(60)
    edges = mesh_edges(torch.as_tensor(f))
    g = torch.Generator().manual_seed(0)
    rest = torch.as_tensor(v, dtype=dtype)
    posed = rest + 0.2 * torch.randn(3, *rest.shape, generator=g, dtype=dtype)
    posed[1, edges[5, 1]] = posed[1, edges[5, 0]]  # one edge collapsed to a point
    weights = torch.randn(3, edges.shape[0], generator=g, dtype=dtype)
    out = {}
    for path in ("kernel", "torch"):
        x = posed.clone().requires_grad_(True)
        with _kernels.disabled() if path == "torch" else contextlib.nullcontext():
            d2 = edge_squared_length(x, edges)
            ((d2 * weights).sum() + edge_stretch_loss(x, rest, edges)).backward()
            out[path] = (d2.detach(), x.grad, edge_squared_length(rest, edges))
    assert out["kernel"][0][1, 5] == 1e-18 and out["kernel"][1].abs().sum() > 0
    tol = {"atol": 1e-12, "rtol": 1e-12} if dtype == torch.float64 else {"atol": 1e-6, "rtol": 1e-5}
    for a, b in zip(out["kernel"], out["torch"], strict=True):
        torch.testing.assert_close(a, b, **tol)


def test_edge_length_kernel_gradcheck_and_bad_edges():
    from zooctl.errors import InputError
    from zooctl.fit.losses import _EdgeSquaredLengthKernel, edge_squared_length

    v = torch.randn(2, 7, 3, dtype=torch.float64, requires_grad=True)
    edges = torch.tensor([[0, 1], [1, 2], [2, 0], [3, 6], [6, 4], [4, 3], [5, 0]])
    assert torch.autograd.gradcheck(lambda x: _EdgeSquaredLengthKernel.apply(x, edges), (v,))
    with pytest.raises(InputError, match="edges name vertex 7"):
        edge_squared_length(v, torch.tensor([[0, 7]]))
