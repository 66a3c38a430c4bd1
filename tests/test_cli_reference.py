"""docs/cli.md is what tools/gen_cli_reference.py makes of the CLI as it is now."""

from __future__ import annotations

import importlib.util
import re

from conftest import REPO

spec = importlib.util.spec_from_file_location("gen_cli_reference", REPO / "tools" / "gen_cli_reference.py")
gen = importlib.util.module_from_spec(spec)
spec.loader.exec_module(gen)

REGENERATE = "docs/cli.md is stale: run `.venv/bin/python tools/gen_cli_reference.py` and commit it"


def test_cli_reference_is_current():
    assert gen.OUTPUT.read_text() == gen.render(), REGENERATE


def test_cli_reference_lists_every_command_and_option():
    text = gen.render()
    root = gen._root_command()
    for path, cmd in gen._walk(root, ["zooctl"]):
        assert f"\n## {' '.join(path)}\n" in text
        for p in cmd.params:
            if not getattr(p, "hidden", False):
                assert gen._names(p) in text, (path, p.name)
    assert "`--preset`" in text and "`zooctl fit`" in text


def test_every_environment_variable_zooctl_reads_is_described():
    used = set()
    for f in (REPO / "zooctl").rglob("*.py"):
        used |= set(re.findall(r"\bZOOCTL_[A-Z0-9_]*[A-Z0-9]\b", f.read_text()))
    missing = sorted(used - set(gen.ENVIRONMENT))
    assert not missing, f"describe {missing} in ENVIRONMENT of tools/gen_cli_reference.py, then regenerate"


def test_check_fails_on_a_stale_page(tmp_path):
    page = tmp_path / "cli.md"
    page.write_text(gen.render().replace("`--preset`", "`--preset-old`"))
    assert gen.main(["--check", "-o", str(page)]) == 1
    assert gen.main(["-o", str(page)]) == 0
    assert gen.main(["--check", "-o", str(page)]) == 0
