"""CPU kernels of the renderers (the camera projection included, the contour loss's
nearest-vertex search and the edge-stretch term's edge lengths): plain C++
compiled with the system compiler on first use.

Why not ``torch.utils.cpp_extension.load_inline``: building against the PyTorch headers takes
minutes on a small machine even for a one-line extension (and needs ninja; BENCHMARKS.md,
"Measurements behind code choices"); these sources include no PyTorch header, compile with one
``g++`` call and are called through `ctypes`
on the tensors' raw buffers. Autograd stays in Python (`torch.autograd.Function` in each renderer).

- Build: all ``*.cpp`` here into one shared library, cached as
  ``$TORCH_EXTENSIONS_DIR/zooctl/render-<hash>.so`` (or the user cache dir,
  ``platformdirs.user_cache_dir("zooctl")/kernels``); the hash covers the sources, the flags and
  the compiler's version, so an edit rebuilds. Written to a temporary name and renamed, so
  concurrent first uses are safe. A new build deletes the other builds unused for 30 days
  (`prune`; every use touches its library).
- Fallback: if there is no compiler or the build fails, `library()` returns None (with one
  warning) and the renderers use their pure-PyTorch path, which gives the same results.
- ``ZOOCTL_RENDER_KERNELS=0`` (or the `disabled()` context manager) forces the PyTorch path.
- CPU only: CUDA tensors always take the PyTorch path (same code with ``device="cuda"``).
- Threads: ``torch.get_num_threads()`` plain threads per call (not OpenMP: PyTorch brings its own
  OpenMP runtime and a second pool would fight it); results do not depend on the thread count.
"""

from __future__ import annotations

import contextlib
import ctypes
import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
import threading
import time
import warnings
from collections.abc import Iterator
from pathlib import Path

import torch

SOURCE_DIR = Path(__file__).resolve().parent
# -ffp-contract=off: no fused multiply-add, so the arithmetic rounds exactly like PyTorch's
# elementwise ops (the z-buffer must pick the same face). -fopenmp-simd: honour `omp simd`
# without the OpenMP runtime. -march=native (AVX2 / AVX-512 where present) is retried without
# when the compiler refuses it; the cache hash includes the CPU's model and flags, so a shared
# cache never hands one machine a library built for another.
CXXFLAGS = [
    "-O3",
    "-std=c++17",
    "-shared",
    "-fPIC",
    "-pthread",
    "-ffp-contract=off",
    "-fno-math-errno",
    "-fno-trapping-math",
    "-fopenmp-simd",
]
ARCHFLAGS = ["-march=native"]

_lock = threading.Lock()
_state: dict[str, object] = {}
_disabled_depth = 0

_P = ctypes.c_void_p
_I = ctypes.c_int64
_D = ctypes.c_double
_SIGNATURES = {
    "gather_faces": [_P, _P, _P, _I, _I, _I, _D, _P, _P, _P, _I],
    "gather_faces_backward": [_P, _P, _P, _I, _I, _I, _P, _P, _I],
    "soft_forward": [_P, _P, _I, _I, _I, _I, _D, _P, _I],
    "soft_backward": [_P, _P, _P, _P, _I, _I, _I, _I, _D, _P, _I],
    "zbuffer": [_P, _P, _P, _I, _I, _I, _I, _P, _P, _P, _I],
    "fragments_forward": [_P, _P, _P, _I, _I, _I, _P, _P, _I],
    "fragments_backward": [_P, _P, _P, _P, _P, _I, _I, _I, _I, _P, _P, _I],
    "interpolate_forward": [_P, _P, _P, _P, _I, _I, _I, _I, _P, _I],
    "interpolate_backward": [_P, _P, _P, _P, _P, _I, _I, _I, _I, _P, _P, _I],
    "flow_project_forward": [_P, _P, _P, _I, _I, _I, _P, _I],
    "flow_project_backward": [_P, _P, _P, _P, _I, _I, _I, _P, _P, _I],
    "splat_forward": [_P, _P, _P, _I, _I, _I, _I, _I, _P, _I],
    "splat_backward": [_P, _P, _P, _P, _I, _I, _I, _I, _I, _P, _I],
    "splat_finish_forward": [_P, _P, _I, _D, _I, _I, _I, _P, _I],
    "splat_finish_backward": [_P, _P, _P, _I, _D, _I, _I, _I, _P, _I],
    "nearest_points": [_P, _P, _I, _I, _I, _P, _I],
    "edge_sq_forward": [_P, _P, _I, _I, _I, _P, _I],
    "edge_sq_backward": [_P, _P, _P, _I, _I, _I, _P, _I],
    "to_camera_forward": [_P, _P, _P, _I, _I, _P, _I],
    "to_camera_backward": [_P, _P, _P, _I, _I, _P, _P, _P, _I],
    "face_windows": [_P, _P, _I, _I, _I, _D, _P, _I],
    "project_forward": [_P, _P, _P, _P, _I, _I, _P, _P, _I],
    "project_backward": [_P, _P, _P, _P, _P, _P, _I, _I, _I, _P, _P, _P, _P, _I],
}


def _compiler() -> str | None:
    return os.environ.get("CXX") or shutil.which("g++") or shutil.which("c++") or shutil.which("clang++")


def cache_dir() -> Path:
    """Where built libraries are kept (see the module docstring)."""
    ext = os.environ.get("TORCH_EXTENSIONS_DIR")
    if ext:
        return Path(ext) / "zooctl"
    from platformdirs import user_cache_dir

    return Path(user_cache_dir("zooctl")) / "kernels"


def _sources() -> list[Path]:
    return sorted(SOURCE_DIR.glob("*.cpp"))


def _cpu_signature() -> bytes:
    sig = platform.machine().encode()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.split(":")[0].strip() in ("model name", "flags", "Features"):
                sig += line.encode()
                if line.startswith(("flags", "Features")):
                    break
    except OSError:
        sig += platform.processor().encode()
    return sig


def _build_hash(cxx: str) -> str:
    h = hashlib.sha256()
    for p in sorted(SOURCE_DIR.glob("*.cpp")) + sorted(SOURCE_DIR.glob("*.h")):
        h.update(p.name.encode() + b"\0" + p.read_bytes())
    h.update(" ".join([cxx, *CXXFLAGS, *ARCHFLAGS]).encode())
    h.update(_cpu_signature())
    try:
        h.update(subprocess.run([cxx, "--version"], capture_output=True, timeout=30).stdout)
    except (OSError, subprocess.SubprocessError):
        pass
    return h.hexdigest()[:16]


def build(force: bool = False) -> Path:
    """Compile the kernels (or find the cached build); returns the library path. Raises on failure."""
    cxx = _compiler()
    if cxx is None:
        raise RuntimeError("no C++ compiler found (set CXX or install g++)")
    out_dir = cache_dir()
    lib = out_dir / f"render-{_build_hash(cxx)}.so"
    if lib.exists() and not force:
        with contextlib.suppress(OSError):
            os.utime(lib)  # in use: `prune` keeps it
        return lib
    out_dir.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".render-", suffix=".so", dir=out_dir)
    os.close(fd)
    try:
        for arch in (ARCHFLAGS, []):
            cmd = [cxx, *CXXFLAGS, *arch, f"-I{SOURCE_DIR}", *map(str, _sources()), "-o", tmp]
            res = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
            if res.returncode == 0:
                break
        else:
            raise RuntimeError(f"{' '.join(cmd)} failed:\n{res.stderr[-2000:]}")
        os.replace(tmp, lib)  # atomic: a concurrent build of the same hash writes identical bytes
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    prune(out_dir, keep=lib)
    return lib


def prune(out_dir: Path, keep: Path, max_age_days: float = 30.0) -> list[Path]:
    """Delete builds of other sources, flags or compilers unused for ``max_age_days`` (every load
    touches its library), so edits and upgrades do not pile up libraries; returns those deleted.
    A library deleted while another installation still uses it is rebuilt on its next use."""
    cutoff = time.time() - max_age_days * 86400
    gone = []
    for p in out_dir.glob("render-*.so"):
        try:
            if p != keep and p.stat().st_mtime < cutoff:
                p.unlink()
                gone.append(p)
        except OSError:
            pass
    return gone


def _load() -> ctypes.CDLL | None:
    with _lock:
        if "lib" in _state:
            return _state["lib"]  # type: ignore[return-value]
        lib = None
        try:
            cdll = ctypes.CDLL(str(build()))
            for name, args in _SIGNATURES.items():
                for suffix in ("f32", "f64"):
                    fn = getattr(cdll, f"zk_{name}_{suffix}")
                    fn.argtypes = args
                    fn.restype = None
            lib = cdll
        except Exception as exc:  # noqa: BLE001 - any failure means: use the PyTorch path
            _state["error"] = str(exc)
            warnings.warn(
                f"zooctl renderer CPU kernels unavailable, using the slower PyTorch path: {exc}",
                RuntimeWarning,
                stacklevel=3,
            )
        _state["lib"] = lib
        return lib


def enabled() -> bool:
    """Whether kernels may be used at all (not disabled by environment or `disabled()`)."""
    return _disabled_depth == 0 and os.environ.get("ZOOCTL_RENDER_KERNELS", "1") not in ("0", "false", "no")


def available() -> bool:
    """Whether the kernels are enabled and built (builds them on first call)."""
    return enabled() and _load() is not None


def error() -> str | None:
    """Why the last build failed, if it did."""
    return _state.get("error")  # type: ignore[return-value]


@contextlib.contextmanager
def disabled() -> Iterator[None]:
    """Within this block every renderer takes its pure-PyTorch path (for tests and comparisons)."""
    global _disabled_depth
    _disabled_depth += 1
    try:
        yield
    finally:
        _disabled_depth -= 1


class Kernel:
    """One kernel bound to a dtype: call with tensors (passed as raw pointers) and ints / floats."""

    def __init__(self, fn):
        self._fn = fn

    def __call__(self, *args) -> None:
        conv = []
        for a in args:
            if isinstance(a, torch.Tensor):
                if not a.is_contiguous():  # the C++ side indexes raw row-major buffers
                    raise ValueError("kernel arguments must be contiguous tensors")
                a = a.data_ptr()
            conv.append(a)
        self._fn(*conv, torch.get_num_threads())


def kernel_for(name: str, *tensors: torch.Tensor, indices: tuple[torch.Tensor, ...] = ()) -> Kernel | None:
    """The ``name`` kernel for these tensors, or None when the PyTorch path must be used.

    Kernels apply when every tensor is on the CPU with one dtype, float32 or float64, and every
    tensor in ``indices`` is a CPU int64 tensor.
    """
    dtype = tensors[0].dtype
    if dtype not in (torch.float32, torch.float64) or not enabled():
        return None
    if any(t.device.type != "cpu" or t.dtype != dtype for t in tensors):
        return None
    if any(t.device.type != "cpu" or t.dtype != torch.int64 for t in indices):
        return None
    lib = _load()
    if lib is None:
        return None
    return Kernel(getattr(lib, f"zk_{name}_{'f32' if dtype == torch.float32 else 'f64'}"))
