"""What one stage-2 step costs: operators launched, host syncs, and milliseconds.

    python bench/step.py [--video DIR] [--template NAME] [--steps 30] [--threads 1]
                         [--device cpu|cuda] [--torch-path] [--pair-budget] [--sites N] [--profile N]
                         [--json OUT]

A GPU step of this fit is bound by its host (Python, autograd and the launches) once no kernel
holds the device (BENCHMARKS.md, "One NVIDIA H200"), so the number of operators a step runs is
what a GPU pays for, and it can be counted on any machine; ``--profile`` shows what holds it.
This fits ``--video`` (a `zooctl bench make` folder; default: the shared Fox rendered here at 60
frames x 320 px) with ``--template`` (a shared Quaternius animal, default Wolf) at ``--preset
fast`` to stage-2 iteration 20, then:

- counts one step's operators by phase (forward, backward, optimiser; an operator is an ATen call
  that computes, views and metadata left out) and its host syncs (operators that make the host
  wait for the device: ``item``/``int()`` of a tensor, ``nonzero``, boolean indexing), under a
  `TorchDispatchMode`; ``--sites N`` lists the N forward call sites that run the most;
- times ``--steps`` steps (median ms, after the counted step);
- ``--profile N``: N more steps under torch.profiler, then its operators by total CPU time and by
  their own device time (CPU time on a CPU).

``--torch-path`` turns the CPU kernels off, so the CPU runs what a CUDA device runs (the same
PyTorch expressions: its operator and sync counts are the device path's). ``--pair-budget``: the
renderers take a fixed budget of (face, pixel) pairs (`{"pair_budget": true}`,
`zooctl.render.windows.PairBudget`) instead of counting them at every call, a read-back each.
The fit itself is that of `zooctl fit --template NAME --preset fast`. One JSON line at the end.
"""

from __future__ import annotations

import argparse
import collections
import json
import statistics
import sys
import tempfile
import time
import traceback
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import SHARED, machine  # noqa: E402

# ATen operators that only make views or read metadata: no kernel runs for them.
VIEWS = {
    "view", "_unsafe_view", "reshape", "_reshape_alias", "as_strided", "expand", "t", "transpose",
    "permute", "unsqueeze", "squeeze", "select", "slice", "alias", "detach", "split",
    "split_with_sizes", "unbind", "lift_fresh", "view_as_real", "numpy_T", "unfold",
}  # fmt: skip
# Those that make the host wait for the device's result (a data-dependent size or a scalar read).
SYNCS = {"_local_scalar_dense", "nonzero", "masked_select", "unique", "_unique2", "is_nonzero"}


def _op_name(func) -> str:
    return str(func.overloadpacket.__name__) if hasattr(func, "overloadpacket") else str(func)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--video", default=None, help="a `zooctl bench make` folder (default: Fox, made here)")
    ap.add_argument("--template", default="Wolf", help="a shared Quaternius animal (animals_pack)")
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--torch-path", action="store_true", help="CPU kernels off: the device path")
    ap.add_argument("--pair-budget", action="store_true", help="the renderers' pairs budgeted: no read-back")
    ap.add_argument("--sites", type=int, default=0, help="list the forward call sites running the most")
    ap.add_argument("--json", default=None, help="also write the JSON line here")
    ap.add_argument(
        "--profile",
        type=int,
        default=0,
        help="after the timed steps, N more under torch.profiler: its tables",
    )
    args = ap.parse_args()

    import contextlib

    import torch
    from torch.utils._python_dispatch import TorchDispatchMode

    from zooctl.fit import stages
    from zooctl.fit.config import preset
    from zooctl.fit.inputs import load_bench_video
    from zooctl.fit.run import fit_video
    from zooctl.io.gltf_import import load_gltf
    from zooctl.render import _kernels

    torch.set_num_threads(args.threads)
    pack = SHARED / "assets" / "quaternius" / "animals_pack"
    if not pack.is_dir():
        sys.exit(f"error: the shared Quaternius animals are not at {pack}")
    folder = Path(args.video) if args.video else _make_fox(pack)
    video = load_bench_video(folder)
    template = load_gltf(pack / f"{args.template}.glb", args.template)
    cfg = preset("fast")
    cfg.device = args.device
    cfg.pair_budget = args.pair_budget

    ops: collections.Counter = collections.Counter()
    syncs: collections.Counter = collections.Counter()
    sites: collections.Counter = collections.Counter()
    phase = ["forward"]

    class Count(TorchDispatchMode):
        def __torch_dispatch__(self, func, types, args=(), kwargs=None):
            name = _op_name(func)
            if name not in VIEWS:
                ops[phase[0]] += 1
                # Adam's step counts live on the host whatever the device: reading them waits for nothing
                host = phase[0] == "optimiser" and name == "_local_scalar_dense"
                if not host and (name in SYNCS or (name == "index" and _bool_index(args))):
                    syncs[f"{phase[0]}: {name} at {_site()}"] += 1
                if phase[0] == "forward":
                    sites[_site()] += 1
            return func(*args, **(kwargs or {}))

    orig = stages.StageRunner.step
    seen = {"n": 0}
    times: list[float] = []
    sync = torch.cuda.synchronize if args.device.startswith("cuda") else (lambda: None)

    def step(self, opt, it):
        if self.stage != 2:
            return orig(self, opt, it)
        seen["n"] += 1
        if seen["n"] > 20 + args.steps:
            return _profiled(orig, self, opt, it, seen["n"] - 20 - args.steps, args.profile, sync)
        if seen["n"] != 20:
            sync()
            t = time.perf_counter()
            out = orig(self, opt, it)
            sync()
            if seen["n"] > 20:
                times.append(time.perf_counter() - t)
            return out
        # the counted step: `StageRunner.step` itself, its phases marked as it enters them
        loss_terms, adam_step = self.loss_terms, opt.step

        def forward(*a, **k):
            out = loss_terms(*a, **k)
            phase[0] = "backward"
            return out

        def optimiser(*a, **k):
            phase[0] = "optimiser"  # and the lazy-Adam restore after it
            return adam_step(*a, **k)

        self.loss_terms, opt.step, phase[0] = forward, optimiser, "forward"
        try:
            with Count():
                return orig(self, opt, it)
        finally:
            del self.loss_terms
            opt.step = adam_step

    stages.StageRunner.step = step
    off = _kernels.disabled() if args.torch_path else contextlib.nullcontext()
    with off:
        fit_video(video, template, cfg, pause_at=20 + args.steps + args.profile)
    res = {
        "machine": machine(),
        "torch": torch.__version__,
        "device": args.device,
        "path": ("torch" if args.torch_path or args.device != "cpu" else "cpu kernels")
        + (", pair budget" if args.pair_budget else ""),
        "threads": args.threads,
        "template": args.template,
        "ops": dict(ops) | {"total": sum(ops.values())},
        "host_syncs": sum(syncs.values()),
        "sync_sites": dict(syncs),
        "step_ms_median": round(1000 * statistics.median(times), 2),
        "steps_timed": len(times),
    }
    if args.sites:
        print("forward call sites running the most operators:")
        for site, n in sites.most_common(args.sites):
            print(f"{n:6d}  {site}")
    print(
        f"| {res['path']} | {res['ops']['forward']} / {res['ops']['backward']} / {res['ops']['optimiser']} "
        f"({res['ops']['total']}) | {res['host_syncs']} | {res['step_ms_median']} |"
    )
    line = json.dumps(res)
    print(line)
    if args.json:
        Path(args.json).write_text(line + "\n")


_PROFILER: list = []


def _profiled(orig, runner, opt, it, k: int, n: int, sync):
    """Step ``k`` of ``n`` profiled ones: the profiler starts before the first and, after the last,
    prints its operators by total CPU time and by their own device (else CPU) time."""
    import torch
    from torch.profiler import ProfilerActivity, profile

    if k == 1:
        cuda = [ProfilerActivity.CUDA] if torch.cuda.is_available() else []
        sync()
        _PROFILER.append(profile(activities=[ProfilerActivity.CPU, *cuda]))
        _PROFILER[0].__enter__()
    out = orig(runner, opt, it)
    if k == n:
        sync()
        prof = _PROFILER.pop()
        prof.__exit__(None, None, None)
        table = prof.key_averages()
        own = "self_cuda_time_total" if torch.cuda.is_available() else "self_cpu_time_total"
        print(f"torch.profiler, {n} stage-2 steps:")
        print(table.table(sort_by="cpu_time_total", row_limit=30, max_name_column_width=60))
        print(table.table(sort_by=own, row_limit=25, max_name_column_width=60))
    return out


def _bool_index(args) -> bool:
    import torch

    idx = args[1] if len(args) > 1 else ()
    return any(isinstance(i, torch.Tensor) and i.dtype == torch.bool for i in (idx or ()) if i is not None)


def _site() -> str:
    """The innermost zooctl line running (file:line code)."""
    for f in reversed(traceback.extract_stack()):
        if "/zooctl/" in f.filename:
            return f"{f.filename.split('/zooctl/')[-1]}:{f.lineno} {(f.line or '')[:70]}"
    return "(outside zooctl: autograd or the optimiser)"


def _make_fox(pack: Path) -> Path:
    """The shared Fox rendered as `bench/fit.py speed` renders it (60 frames, 320 px), once."""
    out = Path(tempfile.gettempdir()) / "zooctl-bench-step"
    folder = out / "Fox"
    if not (folder / "video.npz").is_file():
        from zooctl.benchdata.make import make_video
        from zooctl.io.gltf_import import load_gltf

        make_video(load_gltf(pack / "Fox.glb", "Fox"), out, frames=60, size=320, seed=0)
    return folder


if __name__ == "__main__":
    main()
