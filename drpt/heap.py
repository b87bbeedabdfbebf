"""The C heap keeps what a render frees for the next one (glibc's ``mallopt``).

A render ends on the host: its pixel sums are read back into numpy arrays and the image,
its variance and its moments are computed from them (:func:`drpt.render.renderer.finish`),
each an image-sized allocation of 0.1-2 MB at the sizes the equal-time benchmark renders.
glibc's malloc returns freed memory at the top of its heap to the operating system once more
than ``M_TRIM_THRESHOLD`` bytes are free there (by default twice its mmap threshold, a few
megabytes once that threshold has adapted), and serves allocations above ``M_MMAP_THRESHOLD``
(128 KiB, rising up to 32 MiB as such blocks are freed) with fresh mappings. Both adapt to
what the process has freed, so whether a render's arrays reuse mapped pages or get fresh ones,
which the kernel faults in and zeroes on their first write, depends on the process's history.
Where it left them low, every render of a loop faults: 1050-1230 page faults a render on the
corpus's 192x192 ``moment`` renders (their six squared channels) and the Cornell box, 2-4 ms
of a 7-20 ms render (docs/performance.md, "The finish's page faults").

:func:`keep_freed_memory` sets both thresholds (:data:`MMAP_THRESHOLD`,
:data:`TRIM_THRESHOLD`) once per process; the renderer calls it when it is built. Blocks
up to 8 MiB then come from the heap and at most 64 MiB of freed memory stays mapped for
reuse; larger blocks are mapped and returned as before, so a large render's peak memory is
what it was (blocks up to 32 MiB from the heap raised a 2048x2048 render's peak by 16 MB:
freed blocks kept beside new ones), and its page faults are a small share of its time. The
cost is memory: a process that has rendered keeps up to :data:`TRIM_THRESHOLD` bytes it no
longer uses. Where the C library is not glibc (no ``mallopt``), nothing changes.
"""

from __future__ import annotations

import ctypes
from functools import lru_cache

#: ``mallopt`` parameters (glibc's ``malloc.h``)
M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3
#: blocks up to this size come from the heap: a float64 image of six channels up to about
#: 400x400 pixels, of three up to about 590x590
MMAP_THRESHOLD = 8 << 20
#: freed memory at the heap's top up to this size stays mapped for reuse
TRIM_THRESHOLD = 64 << 20


@lru_cache(maxsize=1)
def keep_freed_memory() -> bool:
    """Set glibc's trim and mmap thresholds (once); True where they were set."""
    try:
        # the process's own symbols, the C library's among them (``find_library`` would run
        # ``ldconfig``: 4 ms at the first render)
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mallopt.restype, mallopt.argtypes = ctypes.c_int, [ctypes.c_int, ctypes.c_int]
    # mallopt returns 1 on success; both or neither (a failed one leaves glibc's defaults)
    return bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD))
