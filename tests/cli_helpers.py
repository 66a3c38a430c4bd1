"""Run the real `zooctl` CLI in-process or as a subprocess and capture what a user would see."""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@dataclass
class Result:
    code: int
    out: str
    err: str

    def json(self):
        return json.loads(self.out)


def zooctl(*args: str, store: Path | None = None, env: dict | None = None, timeout: float = 300) -> Result:
    """Run ``python -m zooctl ARGS`` in a subprocess (the console script's exact code path)."""
    e = dict(os.environ)
    e.update({"COLUMNS": "200", "NO_COLOR": "1"})
    if store is not None:
        e["ZOOCTL_STORE"] = str(store)
    if env:
        e.update(env)
    p = subprocess.run(
        [sys.executable, "-m", "zooctl", *args],
        capture_output=True,
        text=True,
        env=e,
        cwd=REPO,
        timeout=timeout,
    )
    return Result(p.returncode, p.stdout, p.stderr)


def run_inprocess(capsys: pytest.CaptureFixture, *args: str) -> Result:
    from zooctl.cli.main import run

    code = run(list(args))
    cap = capsys.readouterr()
    return Result(code, cap.out, cap.err)


def run_in_store(store: Path, *args: str, cwd: Path | None = None) -> int:
    """``zooctl ARGS`` in-process on ``store`` (``ZOOCTL_STORE``), from ``cwd`` if given; the exit
    code. The variable and the folder are restored after (usable where monkeypatch is not: a
    module-scoped fixture)."""
    from zooctl.cli.main import run

    old, old_cwd = os.environ.get("ZOOCTL_STORE"), os.getcwd()
    os.environ["ZOOCTL_STORE"] = str(store)
    try:
        if cwd is not None:
            os.chdir(cwd)
        return run(list(args))
    finally:
        os.chdir(old_cwd)
        if old is None:
            os.environ.pop("ZOOCTL_STORE", None)
        else:
            os.environ["ZOOCTL_STORE"] = old


def pip(*args: str) -> None:
    """Run pip in this venv, as a user installing a plugin package would."""
    subprocess.run(
        [sys.executable, "-m", "pip", "-q", "--disable-pip-version-check", *args],
        check=True,
        capture_output=True,
        timeout=300,
    )


@contextlib.contextmanager
def plugin_installed(folder: Path, dist: str) -> Iterator[None]:
    """pip-install the plugin package in ``folder`` into this venv, exactly as a user would; uninstall
    the distribution ``dist`` after."""
    pip("install", "--no-deps", "--no-build-isolation", str(folder))
    try:
        yield
    finally:
        pip("uninstall", "-y", dist)
