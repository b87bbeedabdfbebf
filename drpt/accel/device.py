"""Device arrays and the ray/box slab test shared by the accelerators.

:func:`device_array` uploads every accelerator's host arrays. Dr.Jit (LLVM)
maps host memory without copying and marks a buffer that is not 64-byte
aligned as *unaligned*; packet gathers (``dr.gather(Array4f, ...)``) from
such a buffer silently fall back to one gather per component. numpy only
guarantees 16 bytes, so the data is placed at an ``align_bytes`` boundary
(:func:`drpt.backend.policy`, 64 on both backends) inside a larger numpy
buffer (Dr.Jit keeps a reference to it), followed by at least
``align_bytes`` zero bytes, so that no packet can end past the allocation.

:func:`slab` is the robust slab test (Ize 2013): the exit distance is
widened by :data:`SLAB_EPS` (4 float32 ulps) so that the rounding of the
six plane distances never makes a ray miss a box it touches.
"""

from __future__ import annotations

import drjit as dr
import numpy as np

from .. import backend

SLAB_EPS = 1.0 + 4.0 * 2.0**-24  # robust slab test (Ize 2013): widen t_far


def device_array(cls, a: np.ndarray, padded: bool = False):
    """Device copy of ``a`` (flattened), aligned and zero padded as in the
    module docstring, evaluated.

    With ``padded`` the zero bytes are part of the device array (its width
    includes them: packets read near the end stay inside the array, as the
    4-wide BVH's node and primitive buffers need); without, the array has
    exactly ``a.size`` entries and the zeros only follow it in memory.
    The alignment is read from :func:`drpt.backend.policy` at each call.
    """
    align = backend.policy().align_bytes
    a = np.ascontiguousarray(a).reshape(-1)
    nb = a.nbytes
    raw = np.zeros(nb + align + align, np.uint8)
    off = (-raw.ctypes.data) % align
    host = raw[off:off + nb + align].view(a.dtype)
    host[:a.size] = a
    v = cls(host if padded else host[:a.size])
    dr.eval(v)
    return v


def nbytes(*arrays) -> int:
    """Device bytes of ``arrays`` (``None`` entries skipped; 8 bytes per entry
    of 64-bit types, else 4), padding included."""
    n = 0
    for a in arrays:
        if a is not None:
            n += dr.width(a) * (8 if "64" in type(a).__name__ else 4)
    return n


def slab(lo, hi, o, inv_d):
    """Entry and widened exit distance ``(tn, tf)`` of rays ``o + t d``
    (``inv_d = 1 / d``) through the boxes ``[lo, hi]`` (three components
    each: Dr.Jit arrays or Python floats). ``tn`` is clamped at 0; ``tf`` is
    multiplied by :data:`SLAB_EPS`. A ray meets the box when ``tn <= tf``."""
    ax = (lo[0] - o[0]) * inv_d[0]
    bx = (hi[0] - o[0]) * inv_d[0]
    ay = (lo[1] - o[1]) * inv_d[1]
    by = (hi[1] - o[1]) * inv_d[1]
    az = (lo[2] - o[2]) * inv_d[2]
    bz = (hi[2] - o[2]) * inv_d[2]
    tn = dr.fmax(dr.fmax(dr.fmax(dr.fmin(ax, bx), dr.fmin(ay, by)), dr.fmin(az, bz)), 0.0)
    tf = dr.fmin(dr.fmin(dr.fmax(ax, bx), dr.fmax(ay, by)), dr.fmax(az, bz)) * SLAB_EPS
    return tn, tf
