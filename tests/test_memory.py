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


def test_cli_refuses_before_rendering(tmp_path, capsys, monkeypatch):
    from drpt.cli import main

    monkeypatch.setattr(memory, "available", lambda: memory.estimate(32, 32))
    out = tmp_path / "x.exr"
    assert main(["render", str(CORNELL), "--size", "64", "64", "--spp", "1", "-q", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("drpt: error: a 64x64 image needs about") and not out.exists()
    assert main(["render", str(CORNELL), "--size", "32", "32", "--spp", "1", "-q", "-o", str(out)]) == 0
