"""docs/plugins.md stays true to zooctl/hookspecs.py: every hook has its section, and every Python
snippet in it compiles."""

from __future__ import annotations

import inspect
import re

from cli_helpers import REPO

from zooctl import hookspecs

DOC = REPO / "docs" / "plugins.md"


def hook_names() -> list[str]:
    return [
        name
        for name, fn in inspect.getmembers(hookspecs, inspect.isfunction)
        if getattr(fn, "zooctl_spec", None) is not None
    ]


def test_every_hookspec_has_a_section():
    text = DOC.read_text()
    sections = set(re.findall(r"^## (\w+)$", text, re.M))
    hooks = set(hook_names())
    assert len(hooks) >= 10
    assert hooks <= sections, f"undocumented hooks: {sorted(hooks - sections)}"
    assert not {s for s in sections if s.startswith("register_")} - hooks, (
        "a section for a hook that does not exist"
    )


def test_snippets_compile():
    blocks = re.findall(r"```python\n(.*?)```", DOC.read_text(), re.S)
    assert len(blocks) >= 10
    for i, code in enumerate(blocks):
        compile(code, f"docs/plugins.md snippet {i}", "exec")
