"""drpt's modules import what they use at module level, without cycles.

The backend is chosen when ``drpt`` is imported (``DRPT_BACKEND``) and by
``drpt.cli.main`` before it imports the parser (``--backend``), so no module needs to
defer an import until a function runs. The few imports that stay inside functions say
why on their line; the module-level imports form no cycle (an import of ``a.b.c`` counts
as importing the packages ``a.b`` and ``a`` too, whose ``__init__`` runs first); and every
module imports on its own, in a fresh interpreter state. ``benchmarks/import_counts.py``
prints the counts. Negative controls: the cycle finder finds a planted cycle, and the
reason check refuses a bare import and a bare ``noqa``.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
MOST_INDENTED = 20  # the bound on drpt imports inside functions (and blocks)


def _counts():
    spec = importlib.util.spec_from_file_location("import_counts", ROOT / "benchmarks/import_counts.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_few_imports_inside_functions_each_with_its_reason():
    ic = _counts()
    found = ic.indented_imports()
    assert len(ic.indented_imports(strings=True)) < MOST_INDENTED  # the grep's count
    assert [f for f in found if not ic.has_reason(f[2])] == []
    assert not ic.has_reason("from .x import y") and not ic.has_reason("from .x import y  # noqa: F401")
    assert ic.has_reason("from .x import y  # cycle: x imports this module")


def test_no_import_cycles():
    ic = _counts()
    g = ic.graph()
    assert len(g) > 100 and g["drpt.render.renderer"] >= {"drpt.options", "drpt.render.chunks"}
    assert ic.cycles(g) == []
    # negative control: the finder sees a cycle, and one made by a package's __init__
    planted = {k: set(v) for k, v in g.items()}
    planted["drpt.render.chunks"].add("drpt.render.renderer")
    assert any({"drpt.render.chunks", "drpt.render.renderer"} <= set(c) for c in ic.cycles(planted))
    assert ic._ancestors("drpt.scene.model") == ["drpt", "drpt.scene"]


def test_every_module_imports_alone():
    """Each module in a state where no drpt module was imported yet (one interpreter, drpt's
    modules removed from ``sys.modules`` before each; Dr.Jit stays loaded)."""
    names = [m for m in _counts().modules() if m != "drpt.__main__"]  # (__main__ runs the CLI)
    code = (
        "import importlib, sys\n"
        "bad = []\n"
        f"for m in {names!r}:\n"
        "    for k in [k for k in sys.modules if k == 'drpt' or k.startswith('drpt.')]:\n"
        "        del sys.modules[k]\n"
        "    try:\n"
        "        importlib.import_module(m)\n"
        "    except ImportError as e:\n"
        "        if e.name not in ('viser',):  # the optional 'view' extra\n"
        "            bad.append(f'{m}: {e!r}')\n"
        "print('\\n'.join(bad))\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                       env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.strip() == ""
