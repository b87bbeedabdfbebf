"""benchmarks/render_loop.py renders one corpus scene in a loop, by drpt and by Mitsuba, and
dumps the process's JIT code (not its timings; skipped without ``../shared/corpus``)."""

from __future__ import annotations

import importlib.util
import sys

import pytest

from support import REPO


def _load():
    sys.path.insert(0, str(REPO / "benchmarks"))  # (its sibling import, as when run)
    spec = importlib.util.spec_from_file_location("render_loop", REPO / "benchmarks" / "render_loop.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["render_loop"] = module
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
def test_render_loop_renders_and_dumps_the_kernels(tmp_path, capsys):
    from support.corpus import CORPUS

    if not (CORPUS / "floating_sphere" / "test_directional_direct.xml").is_file():
        pytest.skip("../shared/corpus/mitsuba-data is not present")
    bench = _load()
    assert bench.main(["test_directional", "--rounds", "1", "--dump", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "drpt floating_sphere/test_directional_direct.xml 192x192 27 spp" in out
    dumps = list(tmp_path.glob("*.bin"))
    assert dumps and all(p.stat().st_size > 0 for p in dumps)
    assert bench.main(["test_directional", "--rounds", "1", "--mitsuba"]) == 0
    assert "mitsuba floating_sphere/test_directional_direct.xml" in capsys.readouterr().out
