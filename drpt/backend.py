"""Which Dr.Jit backend drpt's kernels run on, and the constants tuned for it.

Kernels import their array types from ``drjit.auto``; :func:`select` points
``drjit.auto`` at the chosen backend with ``dr.set_backend``. Types are bound
when a module imports them, so the backend must be chosen *before* any kernel
module is imported: ``import drpt`` selects the one named by the environment
variable ``DRPT_BACKEND`` (``llvm``, the default, or ``cuda``), and the CLI's
``--backend`` calls :func:`select` before it imports a kernel. Choosing
another backend after kernels were imported is an error, not a silent mix.

Backend checks happen before anything is compiled:

* LLVM: Dr.Jit 1.5 loads ``libLLVM`` at run time. It refuses LLVM < 15, and
  with LLVM 15 on AVX-512 machines code generation aborts the whole process
  (``LLVM ERROR: Cannot select ... fminimum``) because Dr.Jit 1.5 emits
  ``llvm.minimum``. Both failures happen deep inside native code, so drpt
  asks for the version first (``drjit.detail.llvm_version()`` compiles
  nothing) and refuses politely.
* CUDA: ``dr.set_backend("cuda")`` succeeds without a GPU; the first kernel
  would then fail. :func:`ensure` asks ``dr.has_backend`` first.

Once LLVM passes, :func:`ensure` tunes how Dr.Jit compiles and launches
kernels (:mod:`drpt.llvm_tuning`: hardware gathers on AMD Zen 3, smaller
blocks of lanes).

:class:`Policy` holds the constants tuned per backend (see :data:`POLICIES`).
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import dataclass

from . import llvm_tuning
from .errors import DrptError

MIN_LLVM = 16
BACKENDS = ("llvm", "cuda")
ENV_VAR = "DRPT_BACKEND"

INSTALL_HINT = (
    "install a newer LLVM (Debian/Ubuntu: 'apt-get install libllvm19') "
    "or point DRJIT_LIBLLVM_PATH at a libLLVM.so of version >= "
    f"{MIN_LLVM}"
)


@dataclass(frozen=True)
class Policy:
    """Constants whose best value depends on the device.

    Attributes:
        max_lanes: samples traced at once, the default of ``--max-lanes``
            (bounds memory: one pass holds this many paths).
        min_lanes: lanes per pass with path regeneration (enough to fill the
            device; fewer, longer lanes balance better on a CPU).
        sample_lanes: whether a camera pass on an accelerator whose packets of
            coherent rays cost less (``coherent_gain``) gives each sample its own
            lane rather than regenerating paths (measured on the CPU).
        inline_max_prims: the largest scene ``--accel auto`` compiles inline
            (every primitive's test unrolled into the kernel).
        local_chunk: entries per ``dr.alloc_local`` array of the BVH stack.
        align_bytes: alignment and zero padding of uploaded node arrays, so
            that packet gathers read aligned memory.
        mitsuba_variant: the Mitsuba 3 variant on the same backend.
    """

    name: str
    max_lanes: int
    min_lanes: int
    sample_lanes: bool
    inline_max_prims: int
    local_chunk: int
    align_bytes: int
    mitsuba_variant: str


POLICIES = {
    # LLVM (CPU, 2 cores measured): see drpt/render/renderer.py for min_lanes
    # and drpt/accel/bvh4.py for local_chunk (larger local arrays crashed
    # Dr.Jit 1.5's LLVM backend).
    "llvm": Policy("llvm", max_lanes=1 << 21, min_lanes=1 << 14, sample_lanes=True, inline_max_prims=64,
                   local_chunk=16, align_bytes=64, mitsuba_variant="llvm_ad_rgb"),
    # CUDA: a GPU needs far more threads in flight than a CPU has lanes.
    # Not tuned by measurement on this project's machines (none has a GPU).
    "cuda": Policy("cuda", max_lanes=1 << 22, min_lanes=1 << 20, sample_lanes=False, inline_max_prims=64,
                   local_chunk=16, align_bytes=64, mitsuba_variant="cuda_ad_rgb"),
}

_name: str | None = None
_checked: set[str] = set()  # backends (and "llvm-version") that ensure() has checked
_bad_env: str | None = None  # an unusable DRPT_BACKEND value, reported by ensure()


def _kernels_imported() -> bool:
    return any(m.startswith(("drpt.render", "drpt.accel", "drpt.geometry")) for m in sys.modules)


def select(name: str) -> None:
    """Point ``drjit.auto`` at backend ``name`` (``"llvm"`` or ``"cuda"``).

    Raises :class:`DrptError` for an unknown name, or for a change of backend
    after kernel modules were imported (their types keep the old backend)."""
    global _name
    name = name.strip().lower()
    if name not in BACKENDS:
        raise DrptError(f"backend must be one of {', '.join(BACKENDS)}, got {name!r}")
    if name == _name:
        return
    if _name is not None and _kernels_imported():
        raise DrptError(f"backend {name!r} requested after drpt's kernels were loaded on "
                        f"{_name!r}: choose it first ({ENV_VAR}={name})")
    import drjit as dr

    dr.set_backend(name)
    _name = name


def select_from_env() -> None:
    """Select the backend named by ``DRPT_BACKEND`` (default ``llvm``)."""
    try:
        select(os.environ.get(ENV_VAR, "llvm") or "llvm")
    except DrptError:
        # a bad value is reported by ensure(), from code that can print it
        global _bad_env
        select("llvm")
        _bad_env = os.environ.get(ENV_VAR)


def select_from_argv(argv: list[str]) -> None:
    """Select the backend that ``--backend NAME`` in ``argv`` names, before any kernel
    module is imported (the command line calls it first).

    Without the flag the backend stays the one ``import drpt`` selected from
    ``DRPT_BACKEND``. A backend other than LLVM is checked at once
    (:func:`ensure`): without a GPU the command stops before it reads or writes
    anything; LLVM is checked by the commands that render."""
    pre = argparse.ArgumentParser(add_help=False, allow_abbrev=False)
    pre.add_argument("--backend", default=None)
    known, _ = pre.parse_known_args(argv)
    if known.backend is not None:
        select(known.backend)
    if name() != "llvm":
        ensure()


def name() -> str:
    """The selected backend's name."""
    if _name is None:
        select_from_env()
    return _name


def policy() -> Policy:
    """The :class:`Policy` of the selected backend."""
    return POLICIES[name()]


def jit_backend():
    """The selected backend as a ``drjit.JitBackend``."""
    import drjit as dr

    return dr.JitBackend.CUDA if name() == "cuda" else dr.JitBackend.LLVM


def llvm_version() -> tuple[int, int, int] | None:
    """The LLVM version Dr.Jit loaded, or ``None`` when it found none."""
    import drjit as dr

    if not dr.has_backend(dr.JitBackend.LLVM):
        return None
    return tuple(dr.detail.llvm_version())


def ensure() -> None:
    """Raise :class:`DrptError` unless the selected backend can run kernels."""
    if _bad_env is not None:
        raise DrptError(f"{ENV_VAR} must be one of {', '.join(BACKENDS)}, got {_bad_env!r}")
    current = name()
    if current in _checked:
        return
    if current == "llvm":
        ensure_llvm()
    else:
        import drjit as dr

        if not dr.has_backend(dr.JitBackend.CUDA):
            raise DrptError("backend cuda (--backend or DRPT_BACKEND): Dr.Jit found no CUDA "
                            "device or driver on this machine (use llvm)")
    _checked.add(current)


def ensure_llvm() -> None:
    """Raise :class:`DrptError` unless Dr.Jit has an LLVM >= ``MIN_LLVM``."""
    if "llvm-version" in _checked:
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
    _checked.add("llvm-version")
    llvm_tuning.apply()


def mitsuba_variant() -> str:
    """The Mitsuba 3 variant on drpt's backend (``llvm_ad_rgb`` or ``cuda_ad_rgb``)."""
    return policy().mitsuba_variant


def set_mitsuba_variant():
    """Import Mitsuba, set :func:`mitsuba_variant`, return the module.

    Raises :class:`DrptError` when Mitsuba or that variant is unavailable."""
    try:
        import mitsuba as mi

        mi.set_variant(mitsuba_variant())
    except Exception as e:  # ImportError, or the variant's backend missing
        raise DrptError(f"Mitsuba has no usable '{mitsuba_variant()}' variant: {e}") from e
    return mi
