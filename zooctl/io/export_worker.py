"""Exports written by a second Python process while the command goes on with other work.

``zooctl animate`` spends most of its time on one core: importing PyTorch, sampling, rendering the
preview. The exporters' own imports (usd-core's) and the writing of the files can run meanwhile
on another. `ExportWorker` starts ``python -m zooctl.io.export_worker`` at once, has it import
what the exporters need (`ExporterSpec.preload`) and hands it assets to write (`write_export`,
the same function a command calls in its own process). An exporter that cannot be sent to another
process (a plugin's lambda) or a worker that is gone is written in this process instead: same
files, same errors, no gain.

Protocol: pickles ``(kind, payload)`` on the worker's stdin, the payload pickled apart so that one
the worker cannot load (a module only the command can import) leaves the stream readable:
``("preload", [callables])``, no reply; ``("export", (asset, [(spec, path, clips), ...]))``,
answered on its stdout by ``("ok", seconds)``, ``("error", exception)`` or ``("unsent", None)``
(the command writes those files itself). The worker ends at the end of its input.
"""

from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterable
from concurrent.futures import Future
from pathlib import Path
from typing import Any

from ..asset import RiggedAsset
from ..components import ExporterSpec

Job = tuple[ExporterSpec, Path, "list[str] | None"]


class ExportWorker:
    """A second process that writes exports; a context manager (leaving it ends the process).

    ``ExportWorker(specs)`` starts it and has it preload ``specs``' libraries; ``submit(asset,
    jobs)`` returns a `Future` of the seconds the writing took, whose ``result()`` re-raises the
    exporter's error (a `zooctl.errors.ZooctlError` keeps its message and hint)."""

    def __init__(self, specs: Iterable[ExporterSpec] = ()):
        self._lock = threading.Lock()
        try:
            self._proc: subprocess.Popen | None = subprocess.Popen(
                [sys.executable, "-m", __name__], stdin=subprocess.PIPE, stdout=subprocess.PIPE
            )
        except (OSError, TypeError, ValueError):  # no interpreter to start (an embedded Python)
            self._proc = None
        preloads = [s.preload for s in specs if s.preload is not None]
        if preloads:
            try:
                self._send(pickle.dumps(("preload", pickle.dumps(preloads))))
            except (pickle.PicklingError, AttributeError, TypeError):
                pass  # a plugin's local function: that exporter imports what it needs when it writes

    def submit(self, asset: RiggedAsset, jobs: list[Job]) -> Future:
        """Write ``asset`` once per ``(spec, path, clips)`` of ``jobs``, in the worker."""
        future: Future = Future()
        try:
            request = pickle.dumps(("export", pickle.dumps((asset, jobs))))
        except (pickle.PicklingError, AttributeError, TypeError):
            request = None  # not for another process: written here, on the thread below

        def run() -> None:
            try:
                reply = self._roundtrip(request) if request is not None else None
                if reply is None or reply[0] == "unsent":
                    reply = ("ok", write_jobs(asset, jobs))
                kind, value = reply
                if kind == "ok":
                    future.set_result(value)
                else:
                    future.set_exception(value)
            except BaseException as exc:  # an error of the in-process fallback reaches result()
                future.set_exception(exc)

        threading.Thread(target=run, name="zooctl-export", daemon=True).start()
        return future

    def close(self) -> None:
        """End the worker: it finishes the file it writes, then exits."""
        proc, self._proc = self._proc, None
        if proc is None:
            return
        try:
            proc.stdin.close()
            proc.wait(timeout=30)
        except (OSError, subprocess.TimeoutExpired):
            proc.kill()
            proc.wait()
        proc.stdout.close()

    def __enter__(self) -> ExportWorker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _send(self, data: bytes) -> bool:
        if self._proc is None:
            return False
        try:
            self._proc.stdin.write(data)
            self._proc.stdin.flush()
            return True
        except OSError:  # the worker is gone
            return False

    def _roundtrip(self, request: bytes) -> tuple[str, Any] | None:
        """The worker's reply to ``request``; None when there is no worker to answer."""
        with self._lock:
            if not self._send(request):
                return None
            try:
                return pickle.load(self._proc.stdout)
            except (EOFError, OSError, pickle.UnpicklingError):
                return None


def write_jobs(asset: RiggedAsset, jobs: list[Job]) -> float:
    """Write every job with `write_export`; returns the seconds it took."""
    from .asset_export import write_export

    t0 = time.perf_counter()
    for spec, path, clips in jobs:
        write_export(spec, asset, path, clips)
    return time.perf_counter() - t0


def _reply(value: tuple[str, Any]) -> bytes:
    try:
        return pickle.dumps(value)
    except Exception:  # an exception that will not pickle: its text still gets through
        from ..errors import ZooctlError

        return pickle.dumps(("error", ZooctlError(f"export failed: {value[1]}")))


def main() -> None:
    """The worker: read requests from stdin until it ends (module docstring)."""
    # Ctrl-C belongs to the command: it closes our input, and we stop at the end of it.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    replies = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)  # whatever an exporter prints goes to stderr, not into the replies
    requests = sys.stdin.buffer
    while True:
        try:
            kind, payload = pickle.load(requests)
        except EOFError:
            return
        try:
            loaded = pickle.loads(payload)
        except Exception:
            loaded = None
        if kind == "preload":
            for preload in loaded or ():
                try:
                    preload()
                except Exception:  # noqa: S112 - the exporter reports it when it writes
                    continue
            continue
        if loaded is None:
            reply: tuple[str, Any] = ("unsent", None)
        else:
            try:
                reply = ("ok", write_jobs(*loaded))
            except Exception as exc:
                reply = ("error", exc)
        replies.write(_reply(reply))
        replies.flush()


if __name__ == "__main__":
    main()
