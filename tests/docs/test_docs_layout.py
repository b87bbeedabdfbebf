"""docs/architecture.md's Layout table names every module of the package under its folder, and
every module it names exists (``__init__.py`` and ``__main__.py`` aside). Negative control: a
table without one module, and one naming a module that does not exist, both fail the check."""

from __future__ import annotations

import re

DOC = "docs/architecture.md"



def _table(text: str) -> dict[str, set[str]]:
    """``{folder: {module file names}}`` from the Layout table's ``drpt/...`` rows."""
    section = text.split("## Layout", 1)[1].split("\n## ", 1)[0]
    rows = {}
    for line in section.splitlines():
        m = re.match(r"\| `(drpt(?:/[^`]*)?)/` \| (.*) \|$", line)
        if m:
            rows[m.group(1)] = set(re.findall(r"`([A-Za-z0-9_]+\.py)`", m.group(2)))
    return rows


def _tree(repo) -> dict[str, set[str]]:
    out: dict[str, set[str]] = {}
    for p in (repo / "drpt").rglob("*.py"):
        if p.name in ("__init__.py", "__main__.py"):
            continue
        out.setdefault(str(p.parent.relative_to(repo)), set()).add(p.name)
    return out


def _problems(table: dict[str, set[str]], tree: dict[str, set[str]]) -> list[str]:
    out = []
    for folder, files in tree.items():
        missing = files - table.get(folder, set())
        if missing:
            out.append(f"{folder}/: not in the table: {sorted(missing)}")
    for folder, files in table.items():
        extra = files - tree.get(folder, set())
        if extra:
            out.append(f"{folder}/: no such module: {sorted(extra)}")
    return out


def test_layout_table_matches_the_tree(repo):
    assert _problems(_table((repo / DOC).read_text()), _tree(repo)) == []


def test_the_check_catches_a_missing_and_an_invented_module(repo):
    table = _table((repo / DOC).read_text())
    tree = _tree(repo)
    table["drpt/render"] = table["drpt/render"] - {"film.py"}
    table["drpt/tools"] = table["drpt/tools"] | {"nonexistent.py"}
    problems = _problems(table, tree)
    assert any("film.py" in p for p in problems) and any("nonexistent.py" in p for p in problems)
