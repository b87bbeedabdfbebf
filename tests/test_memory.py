"""The memory check before a render (drpt/memory.py): an image that cannot
fit in what the machine has available is one error line, before anything is
traced; one that fits renders."""

from __future__ import annotations

from pathlib import Path

import pytest

from drpt import memory
from drpt.errors import DrptError

CORNELL = Path(__file__).resolve().parents[1] / "scenes" / "cornellbox" / "cornellbox.txt"


def test_estimate_grows_with_pixels_only():
    assert memory.estimate(2048, 2048) - memory.estimate(1024, 1024) == memory.BYTES_PER_PIXEL * 3 * 1024 * 1024


def test_available_reads_meminfo(tmp_path):
    f = tmp_path / "meminfo"
    f.write_text("MemTotal: 1000 kB\nMemAvailable:     2048 kB\nSwapFree: 1024 kB\n")
    assert memory.available(str(f)) == 3072 * 1024
    f.write_text("garbage\n")
    assert memory.available(str(f)) is None
    assert memory.available(str(tmp_path / "none")) is None


def test_check_refuses_what_cannot_fit():
    memory.check(64, 64, have=memory.estimate(64, 64))
    with pytest.raises(DrptError, match=r"a 65536x65536 image needs about 720 GiB"):
        memory.check(65536, 65536, have=16 << 30)
    # the size it names fits, one pixel more per side does not
    with pytest.raises(DrptError, match=r"\((\d+)x(\d+) would fit\)") as e:
        memory.check(20000, 10000, have=8 << 30, per_pixel=80)
    import re

    w, h = map(int, re.search(r"\((\d+)x(\d+) would fit", str(e.value)).groups())
    assert abs(w - 2 * h) <= 2
    memory.check(w, h, have=8 << 30, per_pixel=80)
    with pytest.raises(DrptError):
        memory.check(w + 2, h + 2, have=8 << 30, per_pixel=80)


def test_cli_refuses_before_rendering(tmp_path, capsys, monkeypatch):
    from drpt.cli import main

    monkeypatch.setattr(memory, "available", lambda: memory.estimate(32, 32, memory.BYTES_PER_PIXEL_LOCAL))
    out = tmp_path / "x.exr"
    assert main(["render", str(CORNELL), "--size", "64", "64", "--spp", "1", "-q", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("drpt: error: a 64x64 image needs about") and not out.exists()
    assert main(["render", str(CORNELL), "--size", "32", "32", "--spp", "1", "-q", "-o", str(out)]) == 0


def test_render_kinds_have_their_bytes_per_pixel():
    from drpt.options import RenderOptions

    plain = RenderOptions()
    assert memory.bytes_per_pixel(plain, local=True) == memory.BYTES_PER_PIXEL_LOCAL
    assert memory.bytes_per_pixel(plain, local=False) == memory.BYTES_PER_PIXEL
    splat = RenderOptions(filter="gaussian")
    assert memory.bytes_per_pixel(splat, local=True) > memory.BYTES_PER_PIXEL
    assert memory.bytes_per_pixel(RenderOptions(integrator="ptracer"), local=True) == memory.BYTES_PER_PIXEL


@pytest.mark.slow
def test_a_local_render_s_peak_memory_per_pixel(tmp_path, repo):
    """Peak resident memory of a 1 spp render at 1024x1024 and 2048x2048 (``ru_maxrss`` of
    the child process), the difference per pixel: at most BYTES_PER_PIXEL_LOCAL (measured
    66-74 B; the sums are 48). A render that kept each chunk's full-image sums apart, as
    before passes were added straight into the merge, measured 178 B and fails it."""
    import subprocess
    import sys

    peaks = []
    for size in (1024, 2048):
        # a wrapper process whose only child is the render: its children's peak is the render's
        code = ("import resource, subprocess, sys; subprocess.run(sys.argv[1:], check=True); "
                "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)")
        out = subprocess.run([sys.executable, "-c", code, sys.executable, "-m", "drpt", "render", str(CORNELL),
                              "--size", str(size), str(size), "--spp", "1", "-q",
                              "-o", str(tmp_path / f"{size}.exr")], check=True, cwd=repo,
                             capture_output=True, text=True).stdout
        peaks.append(int(out.split()[-1]) * 1024)
    per_pixel = (peaks[1] - peaks[0]) / (2048 * 2048 - 1024 * 1024)
    assert 40 < per_pixel <= memory.BYTES_PER_PIXEL_LOCAL, per_pixel
