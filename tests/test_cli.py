"""CLI basics: help, version, store resolution, error formatting and exit codes."""

from __future__ import annotations

from cli_helpers import REPO, run_inprocess, zooctl

import zooctl as pkg
from zooctl.paths import default_store


def test_help_and_version():
    r = zooctl("--help")
    assert r.code == 0 and "bank" in r.out and "plugins" in r.out and "--store" in r.out
    v = zooctl("--version")
    assert v.code == 0 and v.out.strip() == f"zooctl {pkg.__version__}"
    bare = zooctl()  # no arguments: the help text (click exits 2 for "no command given")
    assert "Usage: zooctl" in bare.out + bare.err and "Traceback" not in bare.err


def test_argument_help_is_shown(capsys):
    """Arguments are documented in --help (click 8.5 erased typer's argument help: pinned < 8.5)."""
    r = run_inprocess(capsys, "fit", "--help")
    assert r.code == 0 and "Video file, image or DAVIS folder" in r.out


def test_usage_errors_exit_2_without_traceback(tmp_path):
    r = zooctl("bank", "frobnicate", store=tmp_path)
    assert r.code == 2 and "No such command" in r.err and "Traceback" not in r.err
    r = zooctl("bank", "list", "--bogus", store=tmp_path)
    assert r.code == 2


def test_store_option_env_and_checkout_default(tmp_path, monkeypatch):
    monkeypatch.delenv("ZOOCTL_STORE", raising=False)
    monkeypatch.chdir(REPO)
    assert default_store() == REPO / "store"
    monkeypatch.setenv("ZOOCTL_STORE", str(tmp_path / "env"))
    assert default_store() == tmp_path / "env"
    # --store wins over the environment
    from gltf_builder import write_tiny_glb

    f = write_tiny_glb(tmp_path / "t.glb")
    r = zooctl("--store", str(tmp_path / "opt"), "bank", "add", str(f), store=tmp_path / "env")
    assert r.code == 0, r.err
    assert (tmp_path / "opt" / "bank" / "index.json").is_file() and not (tmp_path / "env").exists()


def test_internal_failure_exits_1_with_hint(tmp_path, capsys):
    store = tmp_path / "s"
    (store / "bank").mkdir(parents=True)
    (store / "bank" / "index.json").write_text("{not json")
    r = run_inprocess(capsys, "--store", str(store), "bank", "list")
    assert r.code == 1 and "error: the bank index" in r.err and "damaged" in r.err and "bank repair" in r.err
