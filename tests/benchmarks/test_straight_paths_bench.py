"""benchmarks/straight_paths_ab.py: a run on one small corpus scene (not its timings)."""

from __future__ import annotations

import importlib.util

import pytest

from drpt.render import renderer
from drpt.render.integrators.path import PathIntegrator
from support import REPO, SHARED

_spec = importlib.util.spec_from_file_location("straight_paths_ab", REPO / "benchmarks" / "straight_paths_ab.py")
bench = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench)


@pytest.mark.slow
@pytest.mark.skipif(not (SHARED / "corpus").is_dir(), reason="needs ../shared/corpus")
def test_a_run_reports_the_six_ways_and_restores_the_defaults(capsys):
    def settings():
        return (PathIntegrator.branched, PathIntegrator.emitter_first, PathIntegrator.deferred,
                PathIntegrator.cull, renderer.STRAIGHT_PATHS_PER_LANE)

    defaults = settings()
    (row,) = bench.main(["--only", "mesh_attributes_1", "--rounds", "2", "--min-size", "16",
                         "--max-samples", "20000"])
    assert row["identical"]  # the branches, the deferred vertex work and the culling change no pixel
    assert all(len(v) == 2 for v in row["seconds"].values())
    assert len(row["seconds"]) == 6
    assert settings() == defaults
    assert "| mesh_attributes/test_mesh_attributes_1_face_direct.xml | 48x48, " in capsys.readouterr().out
