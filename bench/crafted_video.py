"""Peak memory of the commands that read a stored video, on a crafted one just under the limits.

    .venv/bin/python bench/crafted_video.py [--frames 2400] [--seconds 240]

Writes a consistent video file (every dataset agrees on T frames of 854x480) whose masks take
just under the array read limit once read (T = 2,400: 984 MB of the default 1,024 MB), with a
small box mask on every frame, and frames and flow left as the file's fill value (no disk; a
reader still decodes and allocates every frame it reads). The store indexes it with `video
repair`; then each command runs in a child process and its peak RSS (ru_maxrss) is reported:
`video repair`, `video show`, `video export --what masks`, and `zooctl fit` with the defaults
(stopped after ``--seconds``; 2,400 frames take hours to fit at the default iterations, so
``--iters N`` runs every window's setup, steps and all the outputs to the end with N iterations
a stage). Goal (#54): every peak under 2 GB.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def craft(path: Path, T: int, H: int = 480, W: int = 854) -> None:
    import h5py

    with h5py.File(path, "w") as f:
        f.attrs.update(
            zooctl_kind="video",
            schema_version=1,
            name="crafted",
            fps=15.0,
            source=json.dumps({"path": "crafted", "kind": "video", "sha256": "0" * 64}),
            segmenter=json.dumps({"name": "masks"}),
            flow_estimator=json.dumps({"name": "dis"}),
        )
        f.create_dataset("frames", (T, H, W, 3), np.uint8, chunks=(1, H, W, 3), compression="lzf")
        m = f.create_dataset("masks", (T, H, W), np.uint8, chunks=(1, H, W), compression="gzip")
        box = np.zeros((H, W), np.uint8)
        box[H // 3 : 2 * H // 3, W // 3 : 2 * W // 3] = 1
        for t in range(T):
            m[t] = box
        boxes = np.tile(np.array([W // 3, H // 3, W // 3, H // 3], np.int32), (T, 1))
        f.create_dataset("boxes", data=boxes)
        f.create_dataset("source_indices", data=np.arange(T, dtype=np.int64))
        g = f.create_group("flow")
        for k in ("forward", "backward"):
            g.create_dataset(k, (T - 1, H, W, 2), np.float16, chunks=(1, H, W, 2), compression="lzf")
        for k in ("occlusion_forward", "occlusion_backward"):
            g.create_dataset(k, (T - 1, H, W), np.uint8, chunks=(1, H, W), compression="gzip")


def run(args: list[str], store: Path, limit_s: float | None = None) -> dict:
    env = {**os.environ, "ZOOCTL_STORE": str(store), "PYTHONPATH": str(REPO)}
    t0 = time.perf_counter()
    p = subprocess.Popen(
        [sys.executable, "-m", "zooctl", *args], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
    )
    # wait4 reaps the child with its rusage (Popen.wait would reap it first); stderr drains meanwhile
    chunks: list[bytes] = []
    reader = threading.Thread(target=lambda: chunks.append(p.stderr.read()), daemon=True)
    reader.start()
    while True:
        pid, status, ru = os.wait4(p.pid, os.WNOHANG)
        if pid:
            break
        if limit_s is not None and time.perf_counter() - t0 > limit_s:
            p.send_signal(signal.SIGKILL)
            _, status, ru = os.wait4(p.pid, 0)
            break
        time.sleep(0.5)
    p.returncode = os.waitstatus_to_exitcode(status)  # reaped here: Popen must not wait again
    reader.join(10)
    err = b"".join(chunks).decode()
    return {
        "command": "zooctl " + " ".join(args),
        "exit": os.waitstatus_to_exitcode(status),
        "wall_s": round(time.perf_counter() - t0, 1),
        "peak_mb": round(ru.ru_maxrss / 1024),
        "last_line": (err.strip().splitlines() or [""])[-1][:200],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=2400)
    ap.add_argument("--seconds", type=float, default=240.0, help="how long the fit may run")
    ap.add_argument("--fit-only", action="store_true", help="only `bank seed` and the fit")
    ap.add_argument(
        "--iters",
        type=int,
        default=None,
        help="stage iterations per window (a --config file), so the fit runs to its end: every "
        "window's setup and all the outputs, at the defaults otherwise",
    )
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as d:
        store = Path(d) / "store"
        (store / "videos").mkdir(parents=True)
        craft(store / "videos" / "crafted.h5", a.frames)
        rows = [run(["video", "repair"], store)]
        if not a.fit_only:
            rows.append(run(["video", "show", "crafted"], store))
            out = str(Path(d) / "masks")
            rows.append(run(["video", "export", "crafted", "--what", "masks", "--out", out], store))
        rows.append(run(["bank", "seed"], store))
        fit = ["fit", "crafted"]
        if a.iters is not None:
            cfg = Path(d) / "iters.json"
            cfg.write_text(json.dumps({"stage1": {"iters": a.iters}, "stage2": {"iters": a.iters}}))
            fit += ["--config", str(cfg), "--out", str(Path(d) / "fit")]
        rows.append(run(fit, store, a.seconds))
    for r in rows:
        print(json.dumps(r), flush=True)


if __name__ == "__main__":
    main()
