"""benchmarks/estimator_variants.py: its variants' options (not its measurements)."""

from __future__ import annotations

import importlib.util
import sys

import pytest

from drpt.errors import DrptError
from drpt.options import PathOptions, RenderOptions
from support import REPO

sys.path.insert(0, str(REPO / "benchmarks"))  # (its sibling import, as when run)
_spec = importlib.util.spec_from_file_location("estimator_variants", REPO / "benchmarks" / "estimator_variants.py")
bench = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench)


def test_a_variant_changes_what_it_names_and_nothing_else():
    base = RenderOptions(width=8, height=8, spp=4, path=PathOptions(max_depth=-1))
    assert bench.apply(base, "base") is base
    opts = bench.apply(base, "sampler=ldsampler;path.rr_depth=3;path.max_depth=2")
    assert (opts.sampler, opts.path.rr_depth, opts.path.max_depth) == ("ldsampler", 3, 2)
    assert opts.light_sampler == base.light_sampler and opts.spp == base.spp and base.path.rr_depth == 5
    with pytest.raises(TypeError):  # (a field RenderOptions lacks)
        bench.apply(base, "no_such_field=1")
    with pytest.raises(DrptError):  # (validated: a sampler drpt lacks)
        bench.apply(base, "sampler=sobolish")
