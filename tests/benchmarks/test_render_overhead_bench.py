"""benchmarks/render_overhead.py and benchmarks/loop_recording_ab.py run on one corpus scene
(not their timings; skipped without ``../shared/corpus``)."""

from __future__ import annotations

import importlib.util
import sys

import pytest

from support import REPO


def _load(name: str):
    sys.path.insert(0, str(REPO / "benchmarks"))  # (their sibling import, as when run)
    spec = importlib.util.spec_from_file_location(name, REPO / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture
def corpus_scene(monkeypatch):
    """The scene's name; the functions the benchmarks patch are restored afterwards."""
    import drpt.render.renderer as R
    from drpt.render.loops import decorated
    from support.corpus import CORPUS

    if not (CORPUS / "floating_sphere" / "test_directional_direct.xml").is_file():
        pytest.skip("../shared/corpus/mitsuba-data is not present")
    for owner, name in [(R, "llvm_tuning"), (R, "finish"), (R.Renderer, "_trace_pass"), *decorated()]:
        monkeypatch.setattr(owner, name, owner.__dict__[name])
    return "test_directional_direct"


@pytest.mark.slow
def test_render_overhead_prints_every_phase(corpus_scene, capsys):
    bench = _load("render_overhead")
    assert bench.main(["--rounds", "2", "--only", corpus_scene]) == 0
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if corpus_scene in line)
    assert row.count("|") == len(bench.PHASES) + 3, row  # scene, the phases, the total


@pytest.mark.slow
def test_loop_recording_ab_checks_the_images_and_prints_a_row(corpus_scene, capsys):
    bench = _load("loop_recording_ab")
    assert bench.main(["--rounds", "2", "--only", corpus_scene]) == 0
    out = capsys.readouterr().out
    assert "| floating_sphere/test_directional_direct.xml | 192x192 | 27 |" in out
