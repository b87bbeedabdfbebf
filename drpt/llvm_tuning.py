"""How Dr.Jit's LLVM backend compiles and launches drpt's kernels: drpt's tuning of it.

Two settings of ``libdrjit-core``; what each gains, and how it was measured, is in
docs/performance.md ("Dr.Jit's LLVM settings"):

**The code-generation target.** Dr.Jit compiles every LLVM kernel for the host:
LLVM's name for the CPU and its feature string (``jit_llvm_target_cpu()``,
``jit_llvm_target_features()``), written into each kernel's IR. Every Dr.Jit
gather is an ``llvm.masked.gather``. LLVM compiles it to the AVX2 gather
instruction only where the CPU's tuning says gathers are fast (``fast-gather``:
Intel Skylake and later; AVX-512 CPUs always). Elsewhere it scalarizes each
gather into one test, branch, extract, load and insert per lane, about 50
instructions for 8 lanes. AMD Zen 3 (``znver3``: AVX2, no AVX-512) is such a
CPU, and there the gather instruction is faster. :func:`apply` adds
``+fast-gather`` to the features on the CPUs in :data:`FAST_GATHER_CPUS`, where
it was measured; ``DRPT_FAST_GATHER`` overrides the choice (``1``: add it on any
AVX2 CPU, ``0``: keep Dr.Jit's target). Images are bitwise the same.

**The block size.** Dr.Jit splits a kernel of ``n`` lanes into blocks for its
thread pool: ``2 * cores`` blocks up to 16384 lanes each, then blocks of
``jit_llvm_block_size()`` = 16384 lanes. A path-regeneration pass of a 256x256
image is 65536 lanes: 4 blocks on 2 cores, and a core that finishes its second
block first waits for the other. The renderer launches its path kernel inside
:func:`blocks_for`, which sets the block size to the largest power of two (Dr.Jit's
requirement) that gives each thread at least :data:`BLOCKS_PER_THREAD` blocks, at most
16384: 16 blocks of 4096 lanes there. A fixed 4096 would split a pass of 22500 lanes (the
dining room at 150x150) into 5 blocks and a short sixth, which ran slower.

``benchmarks/codegen_ab.py`` renders with and without each setting in one process.

The target is global to the process (the block size is set only around the
path kernel's launch): Mitsuba's kernels compiled in the same
process get it too, and gain as well. :func:`dr_default` restores
Dr.Jit's own settings for a block; ``bench`` and ``converge`` time Mitsuba
inside it, as Mitsuba ships. Kernels are cached by their IR, which names the
target, so kernels of the two targets never mix.

The functions are C++-mangled exports of ``libdrjit-core.so`` (Dr.Jit 1.5);
where one is missing (another Dr.Jit), or on the CUDA backend, nothing is
changed.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
from collections.abc import Iterator
from dataclasses import dataclass, replace
from functools import lru_cache

import drjit as dr

#: LLVM CPU names where ``+fast-gather`` was measured to pay (AVX2 without AVX-512).
FAST_GATHER_CPUS = ("znver3",)
FEATURE = "+fast-gather"
ENV_VAR = "DRPT_FAST_GATHER"
#: Blocks of Dr.Jit's thread pool per thread, at least, for the renderer's path kernel.
BLOCKS_PER_THREAD = 8
MAX_BLOCK = 16384  # Dr.Jit's default block size


@dataclass(frozen=True)
class Settings:
    """The LLVM backend's settings that :func:`apply` tunes."""

    cpu: str
    features: str
    block_size: int


_default: Settings | None = None  # Dr.Jit's own settings, before apply()


@lru_cache(maxsize=1)
def core() -> ctypes.CDLL | None:
    """``libdrjit-core.so`` with the functions bound, or ``None``."""
    try:
        lib = ctypes.CDLL(os.path.join(os.path.dirname(dr.__file__), "libdrjit-core.so"))
        lib.target_cpu = lib._Z19jit_llvm_target_cpuv
        lib.target_features = lib._Z24jit_llvm_target_featuresv
        lib.set_target = lib._Z19jit_llvm_set_targetPKcS0_j
        lib.vector_width = lib._Z21jit_llvm_vector_widthv
        lib.block_size = lib._Z19jit_llvm_block_sizev
        lib.set_block_size = lib._Z23jit_llvm_set_block_sizej
    except (OSError, AttributeError):
        return None
    lib.target_cpu.restype = lib.target_features.restype = ctypes.c_char_p
    lib.set_target.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_uint32]
    lib.vector_width.restype = lib.block_size.restype = ctypes.c_uint32
    lib.set_block_size.argtypes = [ctypes.c_uint32]
    for f in (lib.target_cpu, lib.target_features, lib.vector_width, lib.block_size):
        f.argtypes = []
    lib.set_target.restype = lib.set_block_size.restype = None
    return lib


def current() -> Settings | None:
    """The LLVM backend's settings now (``None``: not available)."""
    lib = core()
    if lib is None or not _llvm_ready():
        return None
    cpu = lib.target_cpu()
    if cpu is None:
        return None
    return Settings(cpu.decode(), (lib.target_features() or b"").decode(), lib.block_size())


def block_size_for(n: int, threads: int, width: int) -> int:
    """The block size for a kernel of ``n`` lanes on ``threads`` threads with
    packets of ``width`` lanes: the largest power of two, at most
    :data:`MAX_BLOCK` and above ``width``, that makes at least
    :data:`BLOCKS_PER_THREAD` blocks per thread."""
    b = MAX_BLOCK
    while b > 2 * width and n < b * BLOCKS_PER_THREAD * max(threads, 1):
        b //= 2
    return b


@contextlib.contextmanager
def blocks_for(n: int) -> Iterator[None]:
    """Kernels launched inside the block (of ``n`` lanes) use
    :func:`block_size_for`'s block size; a no-op off the LLVM backend."""
    lib = core()
    if lib is None or not _llvm_ready():
        yield
        return
    before = lib.block_size()
    lib.set_block_size(block_size_for(n, dr.thread_count(), lib.vector_width()))
    try:
        yield
    finally:
        lib.set_block_size(before)


def tuned_features(cpu: str, features: str, env: str | None = None) -> str:
    """``features`` with :data:`FEATURE` added where it pays (see the module
    docstring); ``env`` is the value of ``DRPT_FAST_GATHER`` (``None``: unset)."""
    flags = features.split(",") if features else []
    if FEATURE in flags or "+avx2" not in flags or "+avx512f" in flags:
        return features  # already on, no AVX2 gather, or AVX-512 (gathers are used)
    env = (env or "").strip()
    if env == "0":
        return features
    if env == "1" or cpu in FAST_GATHER_CPUS:
        return ",".join(flags + [FEATURE])
    return features


def apply() -> Settings | None:
    """Tune the LLVM backend for drpt's kernels, once per process (later calls
    change nothing). Returns the settings now in effect."""
    global _default
    now = current()
    if now is None or _default is not None:
        return now
    _default = now
    _set(replace(now, features=tuned_features(now.cpu, now.features, os.environ.get(ENV_VAR))))
    return current()


def fast_gather() -> bool:
    """Whether kernels are compiled with :data:`FEATURE` now."""
    now = current()
    return now is not None and FEATURE in now.features.split(",")


@contextlib.contextmanager
def dr_default() -> Iterator[None]:
    """Dr.Jit's own settings inside the block (a no-op before :func:`apply`)."""
    saved = current()
    if _default is None or saved is None:
        yield
        return
    _set(_default)
    try:
        yield
    finally:
        _set(saved)


def _set(s: Settings) -> None:
    if s.block_size & (s.block_size - 1):
        raise ValueError(f"block size {s.block_size} is not a power of two")  # C++ would abort
    lib = core()
    lib.set_target(s.cpu.encode(), s.features.encode(), lib.vector_width())
    lib.set_block_size(s.block_size)


def _llvm_ready() -> bool:
    # drjit.auto's arrays are on the backend drpt.backend.select chose
    return dr.backend_v(dr.auto.Float) == dr.JitBackend.LLVM and dr.has_backend(dr.JitBackend.LLVM)
