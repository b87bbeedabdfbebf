"""benchmarks/material_dispatch_ab.py: a run on the one-kind control scene (not its timings)."""

from __future__ import annotations

import importlib.util

import pytest

from drpt.render.material import MaterialTable
from support import REPO

_spec = importlib.util.spec_from_file_location("material_dispatch_ab", REPO / "benchmarks" / "material_dispatch_ab.py")
bench = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench)


@pytest.mark.slow
def test_a_run_reports_both_dispatches_and_restores_the_default(capsys):
    (row,) = bench.main(["--only", "cornellbox", "--rounds", "2", "--min-size", "16"])
    assert row["scene"] == "cornellbox" and row["kinds"] == 1
    assert row["identical"] and row["ops_masked"] == row["ops_kinds"] > 0  # one kind: one kernel
    assert all(len(v) == 2 for v in row["seconds"].values())
    assert MaterialTable.dispatch == "kinds"
    assert "| cornellbox | 1 | 16x16, 64 |" in capsys.readouterr().out
