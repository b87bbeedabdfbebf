"""benchmarks/render_variants.py: its variants' options, and a run on one small corpus scene
(not its timings)."""

from __future__ import annotations

import importlib.util
import sys

import pytest

from drpt.options import PathOptions, RenderOptions
from drpt.render.integrators import path
from support import REPO, SHARED

sys.path.insert(0, str(REPO / "benchmarks"))  # (its sibling import, as when run)
_spec = importlib.util.spec_from_file_location("render_variants", REPO / "benchmarks" / "render_variants.py")
bench = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench)


def test_a_variant_changes_what_it_names_and_nothing_else():
    base = RenderOptions(width=8, height=8, spp=4, path=PathOptions(max_depth=6))
    assert bench.options_of(base, "base") == (base, path.UNROLLED_MAX_DEPTH)
    opts, unroll = bench.options_of(base, "max_depth=3,unroll=0,mode=wavefront")
    assert (opts.path.max_depth, opts.mode, unroll) == (3, "wavefront", 0)
    assert opts.path.rr_depth == base.path.rr_depth and opts.spp == base.spp
    with pytest.raises(TypeError):  # (a field RenderOptions lacks)
        bench.options_of(base, "no_such_field=1")


@pytest.mark.slow
@pytest.mark.skipif(not (SHARED / "corpus").is_dir(), reason="needs ../shared/corpus")
def test_a_run_times_every_variant_and_restores_the_unrolled_depth(capsys):
    before = path.UNROLLED_MAX_DEPTH
    # (unroll=8 first: in the second round, reversed, it renders last)
    out = bench.main(["infinite_mirrors/scene_path.xml", "unroll=8", "base", "max_depth=2",
                      "--rounds", "2", "--min-size", "16", "--max-samples", "2000"])
    assert set(out) == {"base", "max_depth=2", "unroll=8"}
    assert out["unroll=8"][1] == 1.0 and all(s > 0 for s, _ in out.values())
    assert path.UNROLLED_MAX_DEPTH == before
    assert "max_depth=2: median " in capsys.readouterr().out
