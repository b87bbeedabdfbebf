"""A pass's lanes as pixels and samples: division by a count the kernel does not fix.

A pass numbers its lanes ``0 .. n-1`` and finds each lane's pixel and its place among the
pixel's lanes as ``lane // m`` and ``lane % m``. The count ``m`` (lanes or samples per
pixel) is kept opaque (``dr.opaque``) so that one kernel serves every pass, whatever its
count; but then LLVM has no constant to divide by, and x86 has no vector integer division:
an opaque ``udiv`` or ``urem`` of a 16-lane packet compiles to sixteen scalar divisions.
:func:`divmod_opaque` divides by multiplying with the divisor's reciprocal in float64
instead (a conversion, an add, a multiply, a truncation), exact over its domain, so the
lanes' pixels and samples, and the images, are those of the integer division bit for bit.

Why it is exact: for ``a = q d + r`` (``0 <= r < d``), ``(a + 1/2) / d = q + (r + 1/2) / d``,
whose fraction lies in ``[1/(2d), 1 - 1/(2d)]``. ``a + 1/2`` is exact in float64, and the
rounded reciprocal and product together are off by a relative ``2^-52`` at most: under
``2^32 * 2^-52 = 2^-20`` absolute, less than ``1/(2d)`` for ``d <= 2^19``. The truncation is
therefore ``q``, and ``a - q d`` is ``r``. :data:`MAX_DIVISOR` keeps a margin; above it the
integer division is used (a Python-time choice: another kernel).
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Float64, UInt32

#: the largest divisor :func:`divmod_opaque` divides by its reciprocal (exact up to 2^19:
#: the module docstring); larger ones divide as integers
MAX_DIVISOR = 1 << 16


def divmod_opaque(a: UInt32, d: int) -> tuple[UInt32, UInt32]:
    """``(a // d, a % d)`` for ``UInt32`` ``a`` and a Python ``d >= 1`` that the kernel
    reads as an opaque value (one kernel for every ``d``), without integer division where
    ``d <= MAX_DIVISOR`` (the module docstring); bit for bit the integer quotient and
    remainder."""
    d = int(d)
    if d < 1:
        raise ValueError(f"divisor {d} < 1")
    dd = dr.opaque(UInt32, d)
    if d > MAX_DIVISOR:
        return a // dd, a % dd
    q = UInt32((Float64(a) + 0.5) * dr.opaque(Float64, 1.0 / d))
    return q, a - q * dd
