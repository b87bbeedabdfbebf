"""Checks that Dr.Jit's LLVM backend is usable before any kernel is compiled.

Dr.Jit 1.5 loads ``libLLVM`` at run time. It refuses LLVM < 15, and with LLVM
15 on AVX-512 machines code generation aborts the whole process
(``LLVM ERROR: Cannot select ... fminimum``) because Dr.Jit 1.5 emits
``llvm.minimum``. Both failures happen deep inside native code, so drpt asks
for the version first (``drjit.detail.llvm_version()`` does not compile
anything) and refuses politely.
"""

from __future__ import annotations

import os

from .errors import DrptError

MIN_LLVM = 16

INSTALL_HINT = (
    "install a newer LLVM (Debian/Ubuntu: 'apt-get install libllvm19') "
    "or point DRJIT_LIBLLVM_PATH at a libLLVM.so of version >= "
    f"{MIN_LLVM}"
)

_checked = False


def llvm_version() -> tuple[int, int, int] | None:
    """The LLVM version Dr.Jit loaded, or ``None`` when it found none."""
    import drjit as dr

    if not dr.has_backend(dr.JitBackend.LLVM):
        return None
    return tuple(dr.detail.llvm_version())


def ensure_llvm() -> None:
    """Raise :class:`DrptError` unless Dr.Jit has an LLVM >= ``MIN_LLVM``."""
    global _checked
    if _checked:
        return
    version = llvm_version()
    if version is None:
        path = os.environ.get("DRJIT_LIBLLVM_PATH")
        where = f" (DRJIT_LIBLLVM_PATH={path})" if path else ""
        raise DrptError(f"Dr.Jit found no usable libLLVM{where}: {INSTALL_HINT}")
    if version[0] < MIN_LLVM:
        found = ".".join(map(str, version))
        raise DrptError(
            f"Dr.Jit loaded LLVM {found}, which cannot compile Dr.Jit 1.5 kernels "
            f"on this CPU: {INSTALL_HINT}"
        )
    _checked = True
