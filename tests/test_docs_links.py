"""Every relative link in README.md, BENCHMARKS.md and docs/ leads somewhere: the file exists and, for
``page.md#anchor``, the page has that heading (GitHub's anchor rules)."""

from __future__ import annotations

import re

from conftest import REPO

PAGES = [REPO / "README.md", REPO / "BENCHMARKS.md", *sorted((REPO / "docs").glob("*.md"))]
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")


def _anchors(text: str) -> set[str]:
    out = set()
    in_code = False
    for line in text.splitlines():
        if line.startswith("```"):
            in_code = not in_code
        elif not in_code and line.startswith("#"):
            title = line.lstrip("#").strip().lower()
            out.add(re.sub(r"[^\w\- ]", "", title).replace(" ", "-"))
    return out


def _links(text: str) -> list[str]:
    text = re.sub(r"```.*?```", "", text, flags=re.S)  # links inside code are not links
    return LINK.findall(text)


def test_relative_links_resolve():
    broken = []
    for page in PAGES:
        for target in _links(page.read_text()):
            if re.match(r"[a-z]+:", target):
                continue  # https:, mailto:
            path, _, anchor = target.partition("#")
            dest = (page.parent / path).resolve() if path else page
            if not dest.exists():
                broken.append(f"{page.name}: {target} (no such file)")
            elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest.read_text()):
                broken.append(f"{page.name}: {target} (no such heading)")
    assert not broken, "\n".join(broken)


def test_the_user_pages_are_linked_from_the_readme():
    readme = REPO / "README.md"
    linked = {(readme.parent / t.partition("#")[0]).resolve() for t in _links(readme.read_text())}
    for name in ("quickstart", "tutorial", "install", "conventions", "troubleshooting", "cli"):
        assert (REPO / "docs" / f"{name}.md").resolve() in linked, name


def test_the_anchor_rule_matches_githubs():
    assert _anchors("## zooctl bank add\n") == {"zooctl-bank-add"}
    assert _anchors("## `ZOOCTL_STORE`: the store (exit 1)\n") == {"zooctl_store-the-store-exit-1"}
