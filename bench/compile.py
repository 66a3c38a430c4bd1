"""Does `torch.compile` pay for the fit's articulation model? Eager against compiled, one run.

    python bench/compile.py [--device cpu|cuda] [--asset animals_pack/Wolf.glb] [--batch 12]
                            [--steps 30] [--mode default reduce-overhead ...] [--threads N] [--cold]

The fit's stage-2 step poses the template for a window of frames (the casa model: forward
kinematics with stretchable bones and girth, the displacement MLP, skinning) and takes the
gradient through it; the renderers and the losses are C++ kernels or custom autograd functions
that a compiler would stop at. This times that part as the fit builds it (`FitScene`'s options
for ``--preset fast``): the forward and backward of a (batch, J, 4) pose and its root
(`FitScene.pose`) to a scalar of its vertices, eager and under ``torch.compile`` with each
``--mode`` (``reduce-overhead`` adds CUDA graphs on a GPU). It reports the first call's seconds
(the compile; ``--cold`` with an empty cache, as on a new machine, else inductor's cache of
earlier runs), the median step in ms over ``--steps`` after 3 warm-up steps (eager and compiled
steps taken in turn), the ratio to eager, and the largest difference of the posed vertices and of
the gradient, relative to their size (the same function, so rounding only). One JSON line per
mode after a table.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _util import SHARED, machine  # noqa: E402


def _sync(device: str) -> None:
    import torch

    if device.startswith("cuda"):
        torch.cuda.synchronize()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--asset", default="animals_pack/Wolf.glb", help="under the shared Quaternius assets")
    ap.add_argument("--batch", type=int, default=12, help="frames a step (--preset fast: 12)")
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--mode", nargs="+", default=["default"], help="torch.compile modes to time")
    ap.add_argument("--threads", type=int, default=1, help="torch threads (CPU)")
    ap.add_argument("--cold", action="store_true", help="an empty compile cache: what a new machine pays")
    args = ap.parse_args()
    if args.cold:  # before torch is imported: inductor reads it once
        os.environ["TORCHINDUCTOR_CACHE_DIR"] = tempfile.mkdtemp(prefix="zooctl-inductor-")

    import torch

    from zooctl.fit.config import preset
    from zooctl.io.gltf_import import load_gltf
    from zooctl.rig.base import get_articulation_model
    from zooctl.rig.rotations import axis_angle_to_quat, quat_mul

    path = SHARED / "assets" / "quaternius" / args.asset
    if not path.is_file():
        sys.exit(f"error: no asset at {path} (the shared data); give --asset under it")
    torch.set_num_threads(args.threads)
    cfg = preset("fast")
    asset = load_gltf(path, path.stem)
    model = get_articulation_model(
        "casa",
        asset,
        device=args.device,
        hidden=cfg.hidden,
        share_seams=cfg.ablation.share_seams,
        girth=cfg.ablation.girth,
    )
    g = torch.Generator().manual_seed(0)
    rest = model.rest_rotation.detach()
    turn = axis_angle_to_quat(0.3 * torch.randn(args.batch, model.num_joints, 3, generator=g)).to(rest)
    q0 = quat_mul(rest[None].expand_as(turn), turn).contiguous()
    root_q = axis_angle_to_quat(0.5 * torch.randn(args.batch, 3, generator=g)).to(rest)
    root_t = torch.randn(args.batch, 3, generator=g).to(rest)

    def step(fn):
        q, rq, rt = (x.clone().requires_grad_(True) for x in (q0, root_q, root_t))
        v = fn(q, rq, rt)
        loss = (v**2).mean()
        loss.backward()
        return v.detach(), q.grad

    def eager(q, rq, rt):  # as `FitScene.pose`
        return model(q, rq, rt).vertices

    ref_v, ref_g = step(eager)
    fns, rows = {}, {}
    for name in ["eager", *args.mode]:
        fns[name] = eager if name == "eager" else torch.compile(eager, mode=name)
        _sync(args.device)
        t = time.perf_counter()
        v, grad = step(fns[name])
        _sync(args.device)
        rows[name] = {
            "mode": name,
            "first_call_s": round(time.perf_counter() - t, 2),
            "vertices_rel_diff": float((v - ref_v).abs().max() / ref_v.abs().max()),
            "grad_rel_diff": float((grad - ref_g).abs().max() / ref_g.abs().max().clamp_min(1e-12)),
        }
        for _ in range(3):
            step(fns[name])
    # interleaved, one step of each in turn: a busy neighbour slows all of them alike
    times: dict[str, list[float]] = {name: [] for name in fns}
    for _ in range(args.steps):
        for name, fn in fns.items():
            _sync(args.device)
            t = time.perf_counter()
            step(fn)
            _sync(args.device)
            times[name].append(time.perf_counter() - t)
    for name in fns:
        rows[name]["step_ms"] = round(1e3 * statistics.median(times[name]), 2)
    rows = list(rows.values())
    base = rows[0]["step_ms"]
    print(
        f"# {machine()}, torch {torch.__version__}, {args.device}, {args.threads} thread(s); "
        f"{path.stem}: {asset.num_vertices} vertices, {model.num_joints} joints, batch {args.batch}"
    )
    print(f"{'mode':<18}{'first call s':>14}{'step ms':>10}{'x eager':>9}{'verts diff':>12}{'grad diff':>11}")
    for r in rows:
        print(
            f"{r['mode']:<18}{r['first_call_s']:>14.2f}{r['step_ms']:>10.2f}{r['step_ms'] / base:>9.2f}"
            f"{r['vertices_rel_diff']:>12.1e}{r['grad_rel_diff']:>11.1e}"
        )
    for r in rows:
        print(
            json.dumps(
                dict(r, device=args.device, asset=path.stem, batch=args.batch, torch=torch.__version__)
            )
        )


if __name__ == "__main__":
    main()
