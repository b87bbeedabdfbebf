"""docs/architecture.md's Layout table names every module of the package under its folder, and
every module it names exists (``__init__.py`` and ``__main__.py`` aside); its Tools paragraph,
which says what each module of ``drpt/tools/`` is for, names every one of them and each of its
folders. Negative controls: a table without one module, and one naming a module that does not
exist, both fail the check; so does the Tools paragraph without one of the modules."""

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


def _tools_missing(paragraph: str, repo) -> list[str]:
    """The modules (by name) and folders of ``drpt/tools/`` that ``paragraph`` does not name."""
    tools = repo / "drpt" / "tools"
    names = [p.stem for p in tools.glob("*.py") if p.name != "__init__.py"]
    folders = [p.name for p in tools.iterdir() if p.is_dir() and (p / "__init__.py").exists()]
    return [n for n in names if f"`{n}`" not in paragraph and f"`{n}.py`" not in paragraph] + \
        [f for f in folders if f"`{f}/`" not in paragraph]


def test_tools_paragraph_names_every_tool_module(repo):
    text = (repo / DOC).read_text()
    paragraph = text.split("**Tools** (`drpt/tools/`)", 1)[1].split("\n\n", 1)[0]
    assert _tools_missing(paragraph, repo) == []
    assert _tools_missing(paragraph.replace("`xmlref`", "xmlref"), repo) == ["xmlref"]  # the control
