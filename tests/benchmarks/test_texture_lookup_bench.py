"""benchmarks/texture_lookup.py times every storage of a texture on a small image and checks
that each gives the first one's values (not its timings)."""

from __future__ import annotations

import importlib.util

from support import REPO


def test_texture_lookup_times_every_variant(capsys):
    spec = importlib.util.spec_from_file_location("texture_lookup", REPO / "benchmarks" / "texture_lookup.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    assert bench.main(["--size", "32", "--lookups", "4096", "--rounds", "1"]) == 0
    out = capsys.readouterr().out
    for kind in ("random", "rows"):
        assert f"{kind} rgb" in " ".join(out.split()) and "codes sRGB" in out and "footprints" in out
