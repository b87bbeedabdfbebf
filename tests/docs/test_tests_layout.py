"""``tests/`` mirrors the package, as docs/architecture.md's "Tests" section says: every folder
of ``tests/`` is a package folder or module of ``drpt/`` (``tests/render/bsdf/`` for
``drpt/render/bsdf/``, ``tests/cli/`` for ``drpt/cli.py``) or one of the folders that section
lists, every test file in ``tests/`` itself is named for a top-level module
(``test_imageio.py`` for ``drpt/imageio.py``), and no two test files share a name (pytest
imports them by name). Negative control: a flat test file of no module, a folder of no module
and a duplicated name each fail the check.

No file of ``tests/`` imports a test module (``from test_x import ...``, ``import test_x``):
such an import finds the module only when pytest happened to import it first (its folder on
``sys.path``), so the importing file fails when run alone. Helpers that several test files
share are in the ``support`` package. Negative control: both forms, at module level and in a
function, are caught; imports of ``support`` and of ``drpt.testing`` are not."""

from __future__ import annotations

import ast
import re
from pathlib import Path

DOC = "docs/architecture.md"


def _section(repo: Path) -> str:
    return (repo / DOC).read_text().split("\n## Tests\n", 1)[1].split("\n## ", 1)[0]


def _extra_folders(section: str) -> set[str]:
    """The folders of the section's table: ``| `tests/NAME/` | ... |``."""
    return set(re.findall(r"^\| `tests/([a-z_]+)/` \|", section, re.M))


def _problems(tests: Path, drpt: Path, extra: set[str]) -> list[str]:
    out = []
    for d in sorted(p for p in tests.rglob("*") if p.is_dir()):
        rel = d.relative_to(tests)
        if rel.parts[0] in extra or "__pycache__" in rel.parts:
            continue
        if not ((drpt / rel).is_dir() or (drpt / rel).with_suffix(".py").is_file()):
            out.append(f"tests/{rel.as_posix()}/ mirrors no drpt/{rel.as_posix()}[.py]")
    for f in sorted(tests.glob("test_*.py")):
        if not (drpt / f.name.removeprefix("test_")).is_file():
            out.append(f"tests/{f.name} names no top-level module drpt/{f.name.removeprefix('test_')}: "
                       "move it to the folder of what it tests")
    seen: dict[str, Path] = {}
    for f in sorted(tests.rglob("test_*.py")):
        if f.name in seen:
            out.append(f"{f.relative_to(tests.parent)} and {seen[f.name].relative_to(tests.parent)} share a name")
        seen.setdefault(f.name, f)
    return out


def _test_module_imports(tests: Path) -> list[str]:
    """``file:line: import`` for every import of a test module (``test_*``) in ``tests``."""
    out = []
    for f in sorted(tests.rglob("*.py")):
        for node in ast.walk(ast.parse(f.read_text(), str(f))):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                if name.split(".")[0].startswith("test_"):
                    out.append(f"{f.relative_to(tests.parent)}:{node.lineno}: imports test module {name}: "
                               "move what it shares to tests/support/")
    return out


def test_tests_mirror_the_package(repo):
    extra = _extra_folders(_section(repo))
    assert {"validation", "robustness", "docs", "support", "data"} <= extra
    assert _problems(repo / "tests", repo / "drpt", extra) == []


def test_the_check_catches_a_misplaced_test(repo, tmp_path):
    extra = _extra_folders(_section(repo))
    drpt = tmp_path / "drpt"
    (drpt / "render").mkdir(parents=True)
    (drpt / "imageio.py").write_text("")
    tests = tmp_path / "tests"
    for f in ("test_imageio.py", "render/test_camera.py", "support/corpus.py"):
        (tests / f).parent.mkdir(parents=True, exist_ok=True)
        (tests / f).write_text("")
    assert _problems(tests, drpt, extra) == []
    (tests / "test_everything.py").write_text("")
    (tests / "misc").mkdir()
    (tests / "validation").mkdir()
    (tests / "validation" / "test_camera.py").write_text("")
    problems = _problems(tests, drpt, extra)
    assert len(problems) == 3, problems
    assert any("test_everything.py" in p for p in problems)
    assert any("tests/misc/" in p for p in problems)
    assert any("share a name" in p for p in problems)


def test_no_test_file_imports_another(repo):
    assert _test_module_imports(repo / "tests") == []


def test_the_check_catches_an_import_of_a_test_module(tmp_path):
    tests = tmp_path / "tests"
    (tests / "render").mkdir(parents=True)
    (tests / "render" / "test_ok.py").write_text(
        "from drpt.testing import assert_agree\nfrom support.xml import XML\nimport support.corpus\n"
        "NAME = 'test_other'\n")
    assert _test_module_imports(tests) == []
    (tests / "render" / "test_a.py").write_text("def f():\n    from test_other import helper\n")
    (tests / "render" / "test_b.py").write_text("import test_other as t\n")
    (tests / "render" / "test_c.py").write_text("import os, test_other.sub\n")
    problems = _test_module_imports(tests)
    assert len(problems) == 3, problems
    assert problems[0].startswith("tests/render/test_a.py:2: imports test module test_other")
    assert problems[1].startswith("tests/render/test_b.py:1: ")
    assert problems[2].startswith("tests/render/test_c.py:1: imports test module test_other.sub")
