"""benchmarks/mask_opacity_vs_mitsuba.py: an ``--opacity`` entry is a constant or a bitmap
(no render)."""

from __future__ import annotations

import importlib.util

from support import REPO

_spec = importlib.util.spec_from_file_location("mask_bench", REPO / "benchmarks" / "mask_opacity_vs_mitsuba.py")
bench = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(bench)


def test_opacity_entries():
    assert bench.opacity_xml("0.25", "bilinear", False) == '<float name="opacity" value="0.25"/>'
    tex = bench.opacity_xml("leaf.png", "nearest", True)
    assert 'type="bitmap"' in tex and '"nearest"' in tex and '<boolean name="raw" value="true"/>' in tex
    assert str((REPO / "leaf.png").name) in tex and "opacity" in bench.SCENE.format(opacity=tex, size=8, spp=1)
