"""Docstrings and comments in ``drpt/`` state contracts and reasons, not measured speedups:
a figure such as "1.4x faster", "2-3x slower", "0.93x as fast", "10-80 % faster" or a bare
ratio with decimals ("Cornell box 1.17x", "1.02-1.06x") belongs in docs/performance.md with
its command, commit and CPU (docs/architecture.md, "Tests"). A ratio that is not a
measurement (a formula's value) is written out: "9/4 times", "about 3.1 times".

The check reads every module, class and function docstring (:func:`ast.get_docstring`) and
every comment (:mod:`tokenize`) of ``drpt/`` and matches :data:`SPEEDUP`. Negative control: a
planted module with such figures in a module, class and function docstring and in a comment
is caught, each where it was planted, and the same module with sizes and statistics in their
place ("4x4 blocks", "a 2x2 matrix", "the 99.7% interval", "1.6 times the mean") is not.

The examples in docstrings (``>>>``) run and show their output (:mod:`doctest`).
"""

from __future__ import annotations

import ast
import io
import re
import tokenize

#: A measured speed ratio: a number or range, ``x`` and a comparison of speed; a ratio with
#: decimals (``1.17x``, ``1.02-1.06x``); a percentage faster or slower; a speedup or
#: slowdown "of" or "by" a number.
SPEEDUP = re.compile(
    r"\d+(?:\.\d+)?(?:\s*-\s*\d+(?:\.\d+)?)?\s*x\s+(?:faster|slower|as\s+fast|speedup|slowdown)\b"
    r"|\b\d+\.\d+(?:\s*-\s*\d+\.\d+)?x\b"
    r"|\d+(?:\.\d+)?(?:\s*-\s*\d+(?:\.\d+)?)?\s*%\s+(?:faster|slower)\b"
    r"|\b(?:speedup|slowdown|faster|slower)\s+(?:of|by)\s+~?\d",
    re.I,
)


def speedups(source: str, name: str) -> list[str]:
    """``name:line: text`` for every docstring or comment of ``source`` that quotes a speedup."""
    out = []
    tree = ast.parse(source)
    nodes = [tree, *(n for n in ast.walk(tree)
                     if isinstance(n, (ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)))]
    for node in nodes:
        doc = ast.get_docstring(node, clean=False)
        if doc is None:
            continue
        line = node.body[0].lineno
        for m in SPEEDUP.finditer(doc):
            out.append(f"{name}:{line + doc.count(chr(10), 0, m.start())}: {' '.join(m.group().split())}")
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            for m in SPEEDUP.finditer(tok.string):
                out.append(f"{name}:{tok.start[0]}: {m.group()}")
    return out


def test_no_measured_speedups_in_drpt(repo):
    found = []
    for path in sorted((repo / "drpt").rglob("*.py")):
        found += speedups(path.read_text(), str(path.relative_to(repo)))
    assert found == [], "move these figures to docs/performance.md:\n" + "\n".join(found)


PLANTED = '''"""A module.

The collapsed tree traces
1.4x faster than the binary one."""


class Grid:
    """Skipping empty cells is 10-80 % faster on sparse meshes."""

    def trace(self):
        """Trace; keeping a second stack made it 0.93x as fast (Cornell box 1.17x)."""
        x = 1  # the binary BVH: 2-3x slower
        return x
'''


def test_the_check_catches_planted_speedups():
    found = speedups(PLANTED, "planted.py")
    assert found == ["planted.py:4: 1.4x faster", "planted.py:8: 10-80 % faster",
                     "planted.py:11: 0.93x as fast", "planted.py:11: 1.17x", "planted.py:12: 2-3x slower"], found


def test_the_check_passes_sizes_and_statistics():
    clean = (PLANTED.replace("1.4x faster than", "with 4x4 blocks, like")
             .replace("10-80 % faster on sparse meshes", "outside the 99.7% interval")
             .replace("0.93x as fast (Cornell box 1.17x)", "the longest path 1.6 times the mean")
             .replace("2-3x slower", "a 2x2 matrix"))
    assert speedups(clean, "clean.py") == []



def _modules_with_examples(repo) -> list[str]:
    out = []
    for path in sorted((repo / "drpt").rglob("*.py")):
        if ">>> " in path.read_text():
            parts = path.relative_to(repo).with_suffix("").parts
            out.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return out


def test_docstring_examples_run(repo):
    """Every ``>>>`` example in a docstring of ``drpt/`` gives the output it shows
    (:mod:`doctest`; examples marked ``+SKIP`` are skipped). Negative control: an example
    whose shown output is wrong fails the same runner."""
    import doctest
    import importlib

    names = _modules_with_examples(repo)
    assert "drpt.scene.transform" in names
    for name in names:
        result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
        assert result.failed == 0, f"{name}: {result.failed} of {result.attempted} examples failed"

    wrong = type(doctest)("planted")
    wrong.__doc__ = ">>> 1 + 1\n3\n"
    assert doctest.testmod(wrong, report=False).failed == 1
