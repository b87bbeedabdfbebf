"""The LLVM guard (drpt/backend.py): a clear error, never an abort."""

import glob
import os
import subprocess
import sys

import pytest

from drpt import backend
from drpt.errors import DrptError


@pytest.fixture(autouse=True)
def _reset():
    backend._checked.clear()
    yield
    backend._checked.clear()


def test_old_llvm_is_refused_with_install_hint(monkeypatch):
    monkeypatch.setattr(backend, "llvm_version", lambda: (15, 0, 6))
    with pytest.raises(DrptError, match=r"LLVM 15\.0\.6.*apt-get install libllvm19"):
        backend.ensure_llvm()


def test_missing_llvm_is_refused(monkeypatch):
    monkeypatch.setattr(backend, "llvm_version", lambda: None)
    with pytest.raises(DrptError, match="no usable libLLVM"):
        backend.ensure_llvm()


def test_current_llvm_is_accepted():
    backend.ensure_llvm()
    assert backend.llvm_version()[0] >= backend.MIN_LLVM


OLD = sorted(glob.glob("/usr/lib/*/libLLVM-15.so*") + glob.glob("/usr/lib/*/libLLVM-14.so*"))


@pytest.mark.skipif(not OLD, reason="no old libLLVM on this machine to try")
def test_cli_with_old_llvm_prints_one_line(tmp_path):
    # A real process that loads an old LLVM: exit status 2, one line, no abort.
    env = dict(os.environ, DRJIT_LIBLLVM_PATH=OLD[0])
    scene = os.path.join(os.path.dirname(__file__), "..", "scenes", "cornellbox", "cornellbox.txt")
    r = subprocess.run([sys.executable, "-m", "drpt", "render", scene, "--size", "8", "8",
                        "--spp", "1", "-o", str(tmp_path / "x.png"), "--quiet"],
                       env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2, r.stderr
    assert "libllvm19" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "x.png").exists()
