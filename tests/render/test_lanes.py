"""divmod_opaque (drpt/render/lanes.py): a pass's lane split into pixel and sample by the
divisor's float64 reciprocal is the integer quotient and remainder, bit for bit, at the
numerators where rounding would show (exact multiples and their neighbours, the ends of the
32-bit range) for divisors up to MAX_DIVISOR and past it (the integer division)."""

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Float64, UInt32

from drpt.render.lanes import MAX_DIVISOR, divmod_opaque

TOP = (1 << 32) - 1
DIVISORS = sorted({*range(1, 70), 96, 127, 192, 255, 256, 257, 1000, 4093, 4096, 65521,
                   MAX_DIVISOR - 1, MAX_DIVISOR})


def _numerators(d: int) -> np.ndarray:
    """Multiples of ``d`` and their neighbours from 0 and from the top of the range, every
    remainder of a few quotients, and the range's last values."""
    q = np.arange(0, 2000, dtype=np.uint64)
    qt = np.uint64(TOP // d) - q
    r = np.arange(min(d, 64), dtype=np.uint64)
    a = np.concatenate([q * d, q * d + 1, q * d + d - 1, qt * d, qt * d - 1, qt * d + d - 1,
                        (7 * d + r), (np.uint64(TOP // d) - 3) * d + r,
                        TOP - np.arange(4096, dtype=np.uint64)])
    return np.unique(a[a <= TOP]).astype(np.uint32)


def _check(split, d: int) -> int:
    """How many numerators ``split(a, d)`` gets wrong (quotient or remainder)."""
    a = _numerators(d)
    q, r = split(UInt32(a), d)
    dr.eval(q, r)
    return int(np.count_nonzero((q.numpy() != a // d) | (r.numpy() != a % d)))


@pytest.mark.parametrize("d", DIVISORS)
def test_quotient_and_remainder_are_the_integer_ones(d):
    assert _check(divmod_opaque, d) == 0


@pytest.mark.parametrize("d", [MAX_DIVISOR + 1, 3 * MAX_DIVISOR, 1 << 24])
def test_past_the_reciprocal_domain_the_integer_division(d):
    assert _check(divmod_opaque, d) == 0


def test_a_divisor_below_one_is_refused():
    with pytest.raises(ValueError):
        divmod_opaque(UInt32(1, 2), 0)


def test_negative_control_truncating_the_plain_product_fails():
    """Without the half (the quotient as the product's truncation) the exact multiples of
    some divisors round below and lose one: the numerators above catch it."""

    def plain(a, d):
        q = UInt32(Float64(a) * dr.opaque(Float64, 1.0 / d))
        return q, a - q * dr.opaque(UInt32, d)

    assert sum(_check(plain, d) for d in DIVISORS) > 0
