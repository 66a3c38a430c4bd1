"""The plugin system: entry-point discovery of a pip-installed third-party package, failures that
are reported and skipped, misspelt hooks, ZOOCTL_LOAD_PLUGINS, and attribution in `zooctl plugins`."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest
from cli_helpers import REPO, pip, plugin_installed, zooctl

from zooctl.components import ImporterSpec
from zooctl.errors import PluginError
from zooctl.plugins import PluginManager, hookimpl

EXAMPLE = REPO / "plugins" / "zooctl-example"


@pytest.fixture(scope="module")
def example_installed():
    """pip-install the example plugin into this venv, exactly as a user would; remove it after."""
    with plugin_installed(EXAMPLE, "zooctl-example"):
        yield


def test_builtins_are_registered_through_entry_points():
    r = zooctl("plugins", "--json")
    assert r.code == 0, r.err
    plugins = {p["name"]: p for p in r.json()["plugins"]}
    gltf = plugins["gltf"]
    assert gltf["builtin"] and gltf["distribution"] == "zooctl" and gltf["status"] == "loaded"
    assert gltf["registers"]["importer"] == ["gltf"]


def test_third_party_plugin_is_discovered_and_used(example_installed, tmp_path):
    r = zooctl("plugins", "--json")
    toy = {p["name"]: p for p in r.json()["plugins"]}["toyrig"]
    assert toy["distribution"] == "zooctl-example" and toy["version"] == "0.1.0" and not toy["builtin"]
    mine = {
        "importer": ["toyrig"],
        "renderer": ["pointsplat"],
        "articulation_model": ["rigid"],
        "exporter": ["ply"],
    }
    assert mine.items() <= toy["registers"].items() and "register_commands" in toy["hooks"]
    table = zooctl("plugins")
    assert "zooctl-example" in table.out and "toyrig" in table.out
    # its command and its importer both work through the real CLI
    f = tmp_path / "worm.toyrig"
    assert zooctl("toyrig", "worm", "-o", str(f), "--bones", "5").code == 0
    store = tmp_path / "s"
    add = zooctl("bank", "add", str(f), store=store)
    assert add.code == 0, add.err
    card = zooctl("bank", "show", "worm", "--json", store=store).json()
    assert card["joints"] == 5 and "wiggle" in card["clips"]
    # ZOOCTL_LOAD_PLUGINS restricts third-party plugins; built-ins still load
    r = zooctl("plugins", "--json", env={"ZOOCTL_LOAD_PLUGINS": "somethingelse"})
    toy = {p["name"]: p for p in r.json()["plugins"]}["toyrig"]
    assert toy["status"] == "skipped"
    blocked = zooctl("bank", "add", str(f), "--name", "worm2", store=store, env={"ZOOCTL_LOAD_PLUGINS": ""})
    assert blocked.code == 2 and "unknown file type '.toyrig'" in blocked.err
    r = zooctl("plugins", "--json", env={"ZOOCTL_LOAD_PLUGINS": "zooctl-example"})
    assert {p["name"]: p for p in r.json()["plugins"]}["toyrig"]["status"] == "loaded"


def _install_broken(tmp_path, module_src: str, dist: str) -> Path:
    """pip-install a broken plugin into a private target folder (not the venv), so that tests
    running at the same time in other workers never see it; returns the folder."""
    pkg = tmp_path / dist
    (pkg / dist.replace("-", "_")).mkdir(parents=True)
    (pkg / dist.replace("-", "_") / "__init__.py").write_text(textwrap.dedent(module_src))
    (pkg / "pyproject.toml").write_text(
        textwrap.dedent(
            f"""
            [build-system]
            requires = ["setuptools>=61"]
            build-backend = "setuptools.build_meta"
            [project]
            name = "{dist}"
            version = "9.9"
            [project.entry-points.zooctl]
            {dist.replace("-", "_")} = "{dist.replace("-", "_")}"
            """
        )
    )
    target = tmp_path / "site"
    pip("install", "--no-deps", "--no-build-isolation", "--target", str(target), str(pkg))
    return target


def test_broken_and_misspelt_plugins_are_reported_and_skipped(tmp_path):
    _install_broken(tmp_path, "import this_module_does_not_exist_anywhere\n", "zooctl-broken-import")
    site = _install_broken(
        tmp_path,
        """
        from zooctl.plugins import hookimpl
        @hookimpl
        def register_importerz(register):
            pass
        """,
        "zooctl-misspelt",
    )
    env = {"PYTHONPATH": str(site)}
    r = zooctl("plugins", "--json", env=env)
    assert r.code == 0
    plugins = {p["name"]: p for p in r.json()["plugins"]}
    assert plugins["zooctl_broken_import"]["status"] == "failed"
    assert "ModuleNotFoundError" in plugins["zooctl_broken_import"]["error"]
    assert plugins["zooctl_misspelt"]["status"] == "failed"
    assert "register_importerz" in plugins["zooctl_misspelt"]["error"]
    # the CLI keeps working, and says loudly which plugins were skipped
    help_ = zooctl("--help", env=env)
    assert help_.code == 0
    assert "plugin 'zooctl_broken_import' (zooctl-broken-import) skipped" in help_.err
    assert "register_importerz" in help_.err
    assert zooctl("bank", "list", "--json", store=tmp_path / "s", env=env).code == 0


def test_in_process_registration_and_conflicts():
    pm = PluginManager()
    pm.load_entry_points()

    class Dup:
        @hookimpl
        def register_importers(self, register):
            register(ImporterSpec("gltf", (".glb",), lambda p, n: None))
            register(ImporterSpec("other", (".zzz",), lambda p, n: None))

    pm.register(Dup(), "dup")
    reg = pm.registry
    assert reg.owner[("importer", "gltf")] == "gltf"
    assert reg.importer_for(".zzz").name == "other"
    assert any("already registered" in p for p in reg.problems)

    class Misspelt:
        @hookimpl
        def register_embeders(self, register):
            pass

    with pytest.raises(PluginError, match="register_embeders"):
        pm.register(Misspelt(), "misspelt")

    class Raises:
        @hookimpl
        def register_exporters(self, register):
            raise RuntimeError("boom")

    pm.register(Raises(), "raises")
    reg = pm.registry
    assert pm.infos["raises"].status == "failed" and "boom" in pm.infos["raises"].error
