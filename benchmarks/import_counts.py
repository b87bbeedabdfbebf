"""How drpt's modules import each other: the imports inside functions, and the cycles.

Usage: ``python benchmarks/import_counts.py [--list]``

Prints

* the count of indented ``drpt`` imports, as
  ``grep -rnE "^\\s+(from \\.|from drpt|import drpt)" drpt | wc -l`` counts them (imports
  inside functions, classes and module-level ``if``/``try`` blocks alike, and docstring
  lines that look like one), the same without the docstring lines, and how many of the
  imports lack a ``# reason`` comment on their line (``--list`` lists them all);
* the import cycles among drpt's modules through module-level imports: each strongly
  connected component of the graph whose edges are the ``import`` statements a module runs
  when it is imported (those inside functions and under ``if TYPE_CHECKING:`` excluded).

``tests/package/test_imports.py`` asserts what this prints (fewer than 20 indented imports, each with
its reason; no cycle) and imports every module alone.
"""

from __future__ import annotations

import ast
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
INDENTED = re.compile(r"^\s+(from \.|from drpt|import drpt)")


def modules(root: Path = ROOT) -> dict[str, Path]:
    """``{dotted module name: file}`` of every module of the drpt package."""
    out = {}
    for p in sorted((root / "drpt").rglob("*.py")):
        parts = list(p.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def _string_lines(tree: ast.Module) -> set[int]:
    """Lines inside multi-line string constants (docstrings' examples)."""
    out: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.end_lineno:
            out.update(range(node.lineno + 1, node.end_lineno + 1))
    return out


def indented_imports(root: Path = ROOT, *, strings: bool = False) -> list[tuple[str, int, str]]:
    """``(file, line number, line)`` of every indented drpt import; with ``strings``
    also the lines of docstrings that look like one (what the grep counts)."""
    out = []
    for p in modules(root).values():
        text = p.read_text()
        skip = set() if strings else _string_lines(ast.parse(text))
        for i, line in enumerate(text.splitlines(), 1):
            if INDENTED.match(line) and i not in skip:
                out.append((str(p.relative_to(root)), i, line.strip()))
    return out


def has_reason(line: str) -> bool:
    """A ``# comment`` that says why (not a bare ``noqa``)."""
    comment = line.partition("#")[2].strip()
    return bool(re.sub(r"noqa(: *[A-Z0-9, ]+)?", "", comment).strip(" ()"))


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or \
        (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _module_level_imports(tree: ast.Module):
    """The import statements a module runs when imported: its body's, and those of its
    module-level ``if``/``try``/``with`` blocks (not ``if TYPE_CHECKING:``)."""
    stack = list(tree.body)
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        elif isinstance(node, ast.If):
            if not _is_type_checking(node.test):
                stack.extend(node.body)
            stack.extend(node.orelse)
        elif isinstance(node, ast.Try):
            stack.extend(node.body + node.orelse + node.finalbody)
            for h in node.handlers:
                stack.extend(h.body)
        elif isinstance(node, ast.With):
            stack.extend(node.body)


def _ancestors(name: str) -> list[str]:
    parts = name.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts))]


def graph(root: Path = ROOT) -> dict[str, set[str]]:
    """``{module: modules it imports at module level}`` within drpt. ``from P import n``
    is an edge to ``P.n`` when that is a module, else to ``P``; importing a module also
    runs its packages' ``__init__``, so an edge goes to each package above the target that
    is not above the importer too (those are being imported already)."""
    mods = modules(root)
    out: dict[str, set[str]] = {}
    for name, path in mods.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        edges: set[str] = set()
        for node in _module_level_imports(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                if node.level:
                    base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                    mod = ".".join(base + ([node.module] if node.module else []))
                else:
                    mod = node.module or ""
                targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in mods else mod
                           for a in node.names]
            own = set(_ancestors(name))
            for t in targets:
                edges |= {m for m in (t, *_ancestors(t)) if m in mods and m not in own}
            edges.discard(name)
        out[name] = edges
    return out


def cycles(g: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of ``g`` with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]
    sys.setrecursionlimit(max(10000, sys.getrecursionlimit()))

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in g.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(g):
        if v not in index:
            visit(v)
    return out


def main(argv: list[str]) -> int:
    found = indented_imports()
    grep = indented_imports(strings=True)
    missing = [f for f in found if not has_reason(f[2])]
    print(f"indented drpt import lines (the grep's count): {len(grep)}, "
          f"{len(grep) - len(found)} of them in docstrings")
    print(f"indented drpt imports: {len(found)} (without a # reason: {len(missing)})")
    for file, line, text in (found if "--list" in argv else missing):
        print(f"  {file}:{line}: {text}")
    comps = cycles(graph())
    print(f"import cycles through module-level imports: {len(comps)}")
    for comp in comps:
        print("  " + " <-> ".join(comp))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
