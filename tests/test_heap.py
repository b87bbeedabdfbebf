"""drpt.heap: freed image-sized arrays are reused, not faulted in again.

Each check runs in a fresh interpreter (glibc's thresholds are per process): the same
allocations as a render's host finish (float64 sums, squares and variance of a 192x192
film, a float32 image), repeated 20 times, counting the process's minor page faults. With
:func:`~drpt.heap.keep_freed_memory` none of the repeats faults; the negative control, the
same process without it, faults on every repeat (thousands: each 4 KiB page of each fresh
mapping or trimmed heap)."""

from __future__ import annotations

import subprocess
import sys

import pytest

from drpt import heap

WORK = """
import resource, sys
import numpy as np
if sys.argv[1] == "1":
    from drpt.heap import keep_freed_memory
    assert keep_freed_memory()
def work():
    s = np.empty((192, 192, 3)); s[:] = 1.0
    q = np.empty((192, 192, 6)); q[:] = 1.0
    v = np.empty((192, 192, 3)); v[:] = 1.0
    m = q[..., :3] * 2.0
    im = s.astype(np.float32)
    del s, q, v, m
    return im
work()
r0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(20):
    work()
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - r0)
"""


def _faults(keep: bool) -> int:
    out = subprocess.run([sys.executable, "-c", WORK, "1" if keep else "0"], capture_output=True,
                         text=True, check=True, timeout=120)
    return int(out.stdout.split()[-1])


@pytest.fixture(scope="module")
def glibc():
    if not heap.keep_freed_memory():
        pytest.skip("no glibc mallopt here")


def test_a_renders_freed_arrays_are_reused_without_page_faults(glibc):
    assert _faults(True) < 50  # (a few for Python's own small allocations at most)


def test_without_it_the_same_arrays_fault_again_each_time(glibc):
    # negative control: 20 repeats of about 4.5 MB of fresh pages
    assert _faults(False) > 20 * 500


def test_it_is_set_once_and_says_so():
    assert heap.keep_freed_memory() is heap.keep_freed_memory()
