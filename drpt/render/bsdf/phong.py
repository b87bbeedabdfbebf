"""Energy-conserving modified Phong (Lafortune & Willems 1994).

    f(wi, wo) = kd / pi + ks * (n + 2) / (2 pi) * cos(alpha)^n

``alpha`` is the angle between ``wo`` and ``r = (-wi.x, -wi.y, wi.z)``, the
mirror reflection of ``wi`` about the normal (+z). The specular term is zero
where ``cos(alpha) <= 0`` (also for ``n = 0``, where it is the constant
``1/pi`` on the half-sphere around ``r``). For ``max(kd + ks) <= 1`` the
material reflects at most what it receives (:mod:`drpt.materials.interpret` scales the
file's Kd/Ks so). ``cos(alpha)`` is computed as
``wi.z*wo.z - wi.x*wo.x - wi.y*wo.y``, symmetric in ``wi`` and ``wo``, so
``f`` is exactly reciprocal.

Sampling (as the seed renderer does): with ``u1`` pick the specular lobe with
probability ``P_s = lum(ks) / (lum(kd) + lum(ks))`` (0 when both are black),
else the diffuse one; with ``u2`` draw the direction:

* specular: ``cos(alpha) = u2.y^(1/(n+1))``, ``phi = 2 pi u2.x`` around ``r``;
  density ``pdf_s = (n + 1) / (2 pi) * cos(alpha)^n`` (on ``cos(alpha) > 0``);
* diffuse: cosine-weighted hemisphere, ``pdf_d = cos(theta_o) / pi``.

A direction below the surface (``wo.z <= 0``, only the specular lobe makes
them) is an invalid sample (weight 0). The returned ``pdf`` is always the
mixture ``P_s pdf_s + (1 - P_s) pdf_d`` of *both* strategies evaluated at
``wo`` (what :func:`pdf` returns), and ``weight = eval / pdf``, so MIS with
light sampling sees one consistent density.

Directions are local (+z = shading normal); ``wi`` points to the viewer and
must be above the surface (``wi.z > 0``), else everything is zero.
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array2f, Array3f, Bool, Float

from ..warp import INV_PI, Frame, square_to_cosine_hemisphere
from . import BSDFSample

#: Luminance weights (Rec. 709) used for the lobe-selection probability.
LUM = (0.2126, 0.7152, 0.0722)
INV_TWO_PI = 0.5 / dr.pi


#: Spec fields the material table uploads for this lobe (see :class:`drpt.render.bsdf.BSDF`).
FIELDS = {"kd": "rgb", "ks": "rgb", "ns": "float"}
#: The field the Whitted ambient term multiplies.
COLOR = "kd"
DELTA = False


class PhongParams:
    """Per-lane Phong parameters: diffuse ``kd``, specular ``ks``, exponent ``ns >= 0``."""

    DRJIT_STRUCT = {"kd": Array3f, "ks": Array3f, "ns": Float}

    def __init__(self, kd=None, ks=None, ns=None):
        self.kd = kd if kd is not None else Array3f(0.0)
        self.ks = ks if ks is not None else Array3f(0.0)
        self.ns = ns if ns is not None else Float(1.0)


def params(table, si, active) -> PhongParams:
    """The parameters of the lanes' materials, gathered from the material table."""
    return PhongParams(table.value("kd", si, active), table.value("ks", si, active),
                       table.value("ns", si, active))


def _lum(c: Array3f) -> Float:
    return LUM[0] * c.x + LUM[1] * c.y + LUM[2] * c.z


def specular_probability(p: PhongParams) -> Float:
    """``P_s = lum(ks) / (lum(kd) + lum(ks))``; 0 when both are black."""
    ls = dr.maximum(_lum(p.ks), 0.0)
    total = dr.maximum(_lum(p.kd), 0.0) + ls
    return dr.select(total > 0.0, ls / dr.select(total > 0.0, total, 1.0), 0.0)


def _cos_alpha(wi: Array3f, wo: Array3f) -> Float:
    """cos of the angle between wo and the mirror direction of wi (symmetric)."""
    return wi.z * wo.z - wi.x * wo.x - wi.y * wo.y


def _pow_lobe(c: Float, n: Float) -> Float:
    """``c^n`` for ``c > 0`` (1 at n = 0, never NaN); 0 for ``c <= 0``."""
    cc = dr.select(c > 0.0, dr.minimum(c, 1.0), 1.0)
    return dr.select(c > 0.0, dr.exp2(n * dr.log2(cc)), 0.0)


def _terms(p: PhongParams, wi: Array3f, wo: Array3f):
    """(valid pair, cos(alpha)^n) shared by eval and pdf."""
    ok = (wi.z > 0.0) & (wo.z > 0.0)
    cn = _pow_lobe(_cos_alpha(wi, wo), p.ns)
    return ok, cn


def _eval(p: PhongParams, ok: Bool, cn: Float, wo: Array3f) -> Array3f:
    # kd * (cos/pi) first, as the Lambert lobe does: ks = 0 gives it bit for bit.
    spec = p.ks * ((p.ns + 2.0) * INV_TWO_PI * cn * wo.z)
    return dr.select(ok, p.kd * (INV_PI * wo.z) + spec, 0.0)


def _pdf(p: PhongParams, ok: Bool, cn: Float, wo: Array3f) -> Float:
    ps = specular_probability(p)
    pdf_s = (p.ns + 1.0) * INV_TWO_PI * cn
    pdf_d = wo.z * INV_PI
    return dr.select(ok, ps * pdf_s + (1.0 - ps) * pdf_d, 0.0)


def eval(p: PhongParams, wi: Array3f, wo: Array3f) -> Array3f:
    """``f(wi, wo) * cos(theta_o)``; 0 unless both directions are above the surface."""
    ok, cn = _terms(p, wi, wo)
    return _eval(p, ok, cn, wo)


def pdf(p: PhongParams, wi: Array3f, wo: Array3f) -> Float:
    """Mixture density ``P_s pdf_s + (1 - P_s) pdf_d`` of :func:`sample` at ``wo``."""
    ok, cn = _terms(p, wi, wo)
    return _pdf(p, ok, cn, wo)


def _sample_lobe(r: Array3f, n: Float, u: Array2f) -> Array3f:
    """Direction with density ``(n+1)/(2 pi) cos^n`` around the unit vector ``r``."""
    # cos = u^(1/(n+1)) = exp(x), x = ln(u)/(n+1) <= 0; 1 - cos = -expm1(x) by
    # a series near 0 so that sin stays accurate for large n.
    x = dr.log(dr.maximum(u.y, 1e-38)) / (n + 1.0)
    one_minus = dr.select(x > -1e-3, -x * (1.0 + x * (0.5 + x * (1.0 / 6.0))), 1.0 - dr.exp(x))
    one_minus = dr.clip(one_minus, 0.0, 1.0)
    cos_a = 1.0 - one_minus
    sin_a = dr.safe_sqrt(one_minus * (2.0 - one_minus))
    s, c = dr.sincos(2.0 * dr.pi * u.x)
    return Frame(r).to_world(Array3f(sin_a * c, sin_a * s, cos_a))


def sample(p: PhongParams, wi: Array3f, u1: Float, u2: Array2f) -> BSDFSample:
    """Pick a lobe with ``u1``, a direction with ``u2``; pdf is the mixture pdf."""
    ps = specular_probability(p)
    r = Array3f(-wi.x, -wi.y, wi.z)
    wo_s = _sample_lobe(r, p.ns, u2)
    wo_d = square_to_cosine_hemisphere(u2)
    wo = dr.select(u1 < ps, wo_s, wo_d)

    ok, cn = _terms(p, wi, wo)
    f = _eval(p, ok, cn, wo)
    pd = _pdf(p, ok, cn, wo)
    valid = ok & (pd > 0.0)
    weight = dr.select(valid, f / dr.select(valid, pd, 1.0), 0.0)
    return BSDFSample(wo=wo, weight=weight, pdf=dr.select(valid, pd, 0.0), valid=valid,
                      delta=Bool(False), eta=Float(1.0))
