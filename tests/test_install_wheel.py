"""zooctl installs as a user installs it: `python -m build` makes an sdist and, from it, a wheel
holding every data file the package reads (the C++ kernel sources among them); the wheel installs
into a fresh virtual environment and its `zooctl` command runs from there, not from this checkout.

The fresh environment borrows this environment's third-party packages (a path file naming its
site-packages; their own path files, this checkout's editable install among them, are not read),
so nothing is downloaded and the test stays well under three minutes.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import venv
import zipfile
from pathlib import Path

import pytest
from conftest import REPO

pytestmark = pytest.mark.slow


def _data_files() -> list[str]:
    """The package's files that are not Python source, as paths inside the wheel."""
    pkg = REPO / "zooctl"
    out = []
    for p in pkg.rglob("*"):
        if p.is_file() and p.suffix not in (".py", ".pyc") and "__pycache__" not in p.parts:
            out.append(p.relative_to(REPO).as_posix())
    return sorted(out)


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    pytest.importorskip("build", reason="the `build` package (test extra) makes the wheel")
    out = tmp_path_factory.mktemp("dist")
    # The sdist is built in the checkout (setuptools writes its egg-info there); the wheel from
    # the unpacked sdist in a temporary folder, so a file the sdist forgets is missing from it too.
    res = subprocess.run(
        [sys.executable, "-m", "build", "--no-isolation", "--outdir", str(out), str(REPO)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stdout[-3000:] + res.stderr[-3000:]
    (whl,) = out.glob("zooctl-*.whl")
    assert list(out.glob("zooctl-*.tar.gz")), "no sdist"
    return whl


def test_the_wheel_holds_every_data_file_and_the_entry_points(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    assert "zooctl/render/_kernels/raster.cpp" in names
    missing = [f for f in _data_files() if f not in names]
    assert not missing, f"package data missing from the wheel (pyproject.toml package-data): {missing}"
    ep = next(n for n in names if n.endswith(".dist-info/entry_points.txt"))
    text = zipfile.ZipFile(wheel).read(ep).decode()
    assert "zooctl = zooctl.cli.main:entry" in text and "[zooctl]" in text


def test_the_installed_wheel_runs_outside_the_checkout(wheel, tmp_path):
    env_dir = tmp_path / "env"
    venv.EnvBuilder(with_pip=False).create(env_dir)
    py = env_dir / "bin" / "python"
    purelib = "import sysconfig; print(sysconfig.get_paths()['purelib'])"
    site = Path(subprocess.check_output([py, "-c", purelib], text=True).strip())
    (site / "borrowed.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTHON", "ZOOCTL_"))}
    env["ZOOCTL_LOAD_PLUGINS"] = ""  # this checkout's plugins are editable installs, not here
    env["ZOOCTL_STORE"] = str(tmp_path / "store")

    def run(*args: str | Path, timeout: float = 300) -> subprocess.CompletedProcess:
        res = subprocess.run(args, capture_output=True, text=True, env=env, cwd=tmp_path, timeout=timeout)
        assert res.returncode == 0, f"{args}: {res.stdout[-3000:]}{res.stderr[-3000:]}"
        return res

    pip = ("-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation", "--ignore-installed")
    run(py, *pip, "--disable-pip-version-check", wheel)
    where = run(py, "-c", "import zooctl; print(zooctl.__file__)").stdout.strip()
    assert Path(where).is_relative_to(env_dir), f"zooctl imported from {where}, not from the installed wheel"
    exe = env_dir / "bin" / "zooctl"
    out = run(exe, "--help").stdout
    for group in ("fit", "bank", "video", "animate"):
        assert group in out
    assert run(exe, "bank", "list", "--json").stdout.strip().startswith("[")
    if shutil.which("g++") or shutil.which("c++"):
        # The renderers' kernels build from the installed sources (the build cache is keyed by
        # their content, so a build this machine made from the checkout is reused).
        code = (
            "import pathlib, zooctl.render._kernels as k; "
            f"assert pathlib.Path(k.SOURCE_DIR).is_relative_to({str(env_dir)!r}), k.SOURCE_DIR; "
            "assert k.available(), k.error()"
        )
        run(py, "-c", code, timeout=600)
