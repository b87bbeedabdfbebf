"""Single-precision ``exp``, ``log``, ``erf`` and ``erfinv`` for kernels whose
arguments are known to be in range: unlike Dr.Jit's general versions they do not
handle infinities, NaNs, denormals and both signs at every call (``exp``, the building
block of ``erf``, is exactly 0 where it underflows). Their CPU time and operation counts:
``docs/performance.md``, "Beckmann's sampler". Pure
Dr.Jit, usable in symbolic loops. Their user: Beckmann's visible-normal sampler
(:meth:`drpt.render.bsdf.microfacet.Distribution._slopes11_beckmann`).

Contracts (float32 arguments; the bounds are checked on dense grids, float32
rounding included, by ``tests/render/test_erf32.py``; Dr.Jit's own functions
meet the same bounds there):

* :func:`exp` -- ``e^x`` for ``x <= 88``, relative error below 3e-7 for ``x >=
  -87``, exactly 0 below ``-87`` (:data:`EXP_MIN`; ``e^-87 ~ 1.6e-38`` is near the
  smallest normal float). ``2^n`` times a degree-6 polynomial on ``[-ln2/2,
  ln2/2]`` (Cody-Waite reduction, ``ln 2`` split in two).
* :func:`log` -- natural log of a positive, finite, *normal* ``x``, relative
  error below 4e-7 (near ``x = 1`` too: ``log(1 + f) = f P(f)``). Zero, negative,
  denormal, infinite or NaN ``x`` give meaningless values: callers keep ``x`` in
  range. The mantissa is reduced to ``[sqrt(1/2), sqrt 2)`` by integer arithmetic
  on the bits; a degree-8 polynomial.
* :func:`erf` -- absolute error below 2.5e-7 on the whole real line, odd,
  ``erf(+-inf) = +-1`` (``|x| >= 4`` gives +-1, as float32 rounds ``erf`` there).
  Its *relative* error near 0 is larger (``1 - e^h`` cancels): not for callers
  that need ``erf`` of tiny arguments to full relative precision. ``erf(z) = 1 -
  e^{h(z)}``, ``h = log erfc``, ``h(z) = z P(z)`` with a degree-7 ``P`` on ``[0, 4]``.
* :func:`erfinv` -- for ``|x| <= 1 - 2^-23``, relative error below 5e-7 against
  the exact inverse: M. Giles' single-precision approximation ("Approximating
  the erfinv function", GPU Computing Gems Jade, 2011; the same two polynomials
  in ``w = -log(1 - x^2)`` as Dr.Jit's ``erfinv``) with :func:`log`.

The polynomials of ``exp``, ``log`` and ``erf`` were fitted in float64 by
Lawson's iteratively reweighted least squares (a minimax fit: relative error for
``exp`` and ``log``, absolute error of ``erf``) and rounded to float32; all are
evaluated by Estrin's scheme (:func:`_poly`).
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Float, Int32

# e^r on [-ln2/2, ln2/2], r^0 .. r^6
_EXP_C = (1.0, 1.0, 0.49999991059303284, 0.16666419804096222, 0.04166822507977486,
          0.008374815806746483, 0.0013836845755577087)
# log(1 + f) / f on [sqrt(1/2) - 1, sqrt(2) - 1], f^0 .. f^8
_LOG_C = (1.0, -0.4999997913837433, 0.3333415985107422, -0.25002947449684143, 0.19958417117595673,
          -0.16543738543987274, 0.1491737812757492, -0.14482185244560242, 0.0895991176366806)
# log(erfc(z)) / z on [0, 4], z^0 .. z^7
_ERFC_C = (-1.128380298614502, -0.636597752571106, -0.10291961580514908, 0.019583959132432938,
           -0.0005369323189370334, -0.0010324022732675076, 0.00030880238045938313, -3.144018410239369e-05)
# Giles (2011), single precision: erfinv(x) / x in w - 2.5 (w < 5) and in sqrt(w) - 3
_ERFINV_C1 = (1.50140941, 0.246640727, -0.00417768164, -0.00125372503, 0.00021858087,
              -4.39150654e-06, -3.5233877e-06, 3.43273939e-07, 2.81022636e-08)
_ERFINV_C2 = (2.83297682, 1.00167406, 0.00943887047, -0.0076224613, 0.00573950773,
              -0.00367342844, 0.00134934322, 0.000100950558, -0.000200214257)

_LOG2E = 1.4426950408889634
_LN2_HI = 0.693145751953125  # ln 2 to 16 bits: n * _LN2_HI is exact for |n| < 2^8
_LN2_LO = 1.4286067653e-06
#: Below this :func:`exp` returns 0 (``2^n`` would leave the normal floats).
EXP_MIN = -87.0
#: erf rounds to +-1 in float32 from here on (``erfc(4) ~ 1.5e-8``).
_ERF_Z_MAX = 4.0
#: Bits of sqrt(1/2): :func:`log` reduces the mantissa to [sqrt(1/2), sqrt 2).
_SQRT_HALF_BITS = 0x3F3504F3


def _poly(x, coeffs):
    """``sum_k coeffs[k] x^k`` by Estrin's scheme: ``c_2k + c_2k+1 x`` in pairs, those
    in pairs in ``x^2``, then ``x^4``, ...: a few more operations than Horner's rule
    (the powers of ``x``) in a dependency chain of ``log2 n`` fused multiply-adds
    instead of ``n``, which is what the kernels' SIMD packets wait on."""
    terms = [Float(c) for c in coeffs]
    p = x
    while len(terms) > 1:
        nxt = [dr.fma(terms[k + 1], p, terms[k]) for k in range(0, len(terms) - 1, 2)]
        if len(terms) % 2:
            nxt.append(terms[-1])
        terms = nxt
        if len(terms) > 1:
            p = dr.square(p)
    return terms[0]


def exp(x: Float) -> Float:
    """``e^x`` (see the module's contract: ``x <= 88``; 0 below :data:`EXP_MIN`)."""
    xc = dr.maximum(x, EXP_MIN)
    n = dr.round(xc * _LOG2E)
    r = dr.fma(n, -_LN2_HI, xc)
    r = dr.fma(n, -_LN2_LO, r)
    p = _poly(r, _EXP_C)
    v = dr.reinterpret_array(Float, dr.reinterpret_array(Int32, p) + (Int32(n) << 23))
    return dr.select(x < EXP_MIN, 0.0, v)


def log(x: Float) -> Float:
    """Natural log of a positive normal ``x`` (see the module's contract)."""
    i = dr.reinterpret_array(Int32, x)
    e = (i - _SQRT_HALF_BITS) >> 23
    f = dr.reinterpret_array(Float, i - (e << 23)) - 1.0
    ef = Float(e)
    return dr.fma(ef, _LN2_HI, dr.fma(ef, _LN2_LO, f * _poly(f, _LOG_C)))


def erf(x: Float) -> Float:
    """The error function to an absolute 2e-7 (see the module's contract)."""
    z = dr.minimum(dr.abs(x), _ERF_Z_MAX)
    return dr.mulsign(1.0 - exp(z * _poly(z, _ERFC_C)), x)


def erfinv(x: Float) -> Float:
    """Inverse error function for ``|x| <= 1 - 2^-23`` (Giles; see the module's contract)."""
    w = -log((1.0 - x) * (1.0 + x))
    p1 = _poly(w - 2.5, _ERFINV_C1)
    p2 = _poly(dr.sqrt(w) - 3.0, _ERFINV_C2)
    return dr.select(w < 5.0, p1, p2) * x
