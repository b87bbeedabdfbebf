"""Microfacet distributions: :class:`Distribution`, Mitsuba 3's
``MicrofacetDistribution`` (Beckmann and GGX, isotropic or anisotropic, visible
or all normals sampled), the one implementation every microfacet lobe uses
(``cook_torrance``, ``roughconductor``, ``roughdielectric``, ``roughplastic``,
``principled``, ``principledthin``), and :func:`reflect`.

Directions are local (``+z`` = macro-surface normal), unit length; ``alpha``
is the width of the distribution (for GGX the slope standard deviation /
sqrt 2; *not* an artist's "roughness": each lobe states its mapping, e.g.
:mod:`drpt.render.bsdf.cook_torrance`). Pure Dr.Jit, usable in symbolic loops.
Formulas, sampling and their relation to Mitsuba's: :class:`Distribution`.
Widths are clamped below to :data:`ALPHA_MIN` (Mitsuba's clamp; a lobe may
clamp harder first, as ``principled`` and ``cook_torrance`` do to 1e-3); ``D`` at
``alpha = 1e-4`` peaks at ``1/(pi alpha^2) ~ 3.2e7``, finite in float32, and
cosines down to 1e-6 (and exactly 0: ``G1 = 0``) give finite values.
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array2f, Array3f, Float

from .. import erf32
from ..warp import square_to_uniform_disk_concentric

#: Smallest microfacet alpha used (Mitsuba 3's clamp for its microfacet plugins).
ALPHA_MIN = 1e-4


def reflect(wi: Array3f, m: Array3f) -> Array3f:
    """Mirror ``wi`` about ``m``: ``2 dot(wi, m) m - wi``."""
    return 2.0 * dr.dot(wi, m) * m - wi


# ---------------------------------------------------------------------------
# Mitsuba 3's MicrofacetDistribution: Beckmann and GGX, anisotropic
# ---------------------------------------------------------------------------

#: |erf(x)| bound of the Beckmann slope sampler (``erfinv(+-1)`` is infinite).
_ERF_MAX = 1.0 - 1.2e-7
#: Halley steps of the Beckmann slope sampler after Jakob's initial guess (three keep the
#: sampled CDF within 5e-7 of ``u``, two do not: tests/render/bsdf/test_microfacet.py).
_HALLEY_STEPS = 3


class Distribution:
    """A Beckmann or GGX microfacet distribution with widths ``alpha_u``
    (along the shading frame's ``x``) and ``alpha_v`` (along ``y``): Mitsuba
    3's ``MicrofacetDistribution`` (``include/mitsuba/render/microfacet.h``)
    formula for formula, same conventions, same clamp (``alpha >= 1e-4``, no
    upper clamp; ``alpha_min``).

    ``beckmann`` is a Python ``bool`` (only that distribution's code is
    traced) or a per-lane ``Bool`` (both are traced and selected per lane).
    ``alpha_v=None`` declares the distribution isotropic (``alpha_v =
    alpha_u``; the non-visible sampler then takes the cheaper isotropic
    branch, as Mitsuba's does when both alphas are the same variable).
    ``sample_visible`` (a Python bool) picks what :meth:`sample` and
    :meth:`pdf` mean. ``alpha_min`` is the lower clamp of the widths: Mitsuba's
    microfacet plugins' 1e-4 by default, ``principled``'s 1e-3 for the lobes
    that follow it (``cook_torrance``).

    Formulas (``m`` a microfacet normal, ``v`` a direction,
    ``au, av`` the widths, ``c = m.z``, ``s = (m.x/au)^2 + (m.y/av)^2``)::

        D_beckmann(m) = exp(-s / c^2) / (pi au av c^4)
        D_ggx(m)      = 1 / (pi au av (s + c^2)^2)

    both normalized as ``integral D(m) m.z dm = 1``, and 0 unless
    ``D m.z > 1e-20`` (Mitsuba's cut; removes ``m.z <= 0``). Smith masking,
    with ``t = ((au v.x)^2 + (av v.y)^2) / v.z^2`` (``alpha(phi)^2
    tan^2 theta``)::

        G1_ggx(v, m)      = 2 / (1 + sqrt(1 + t))
        G1_beckmann(v, m) = (3.535 a + 2.181 a^2) / (1 + 2.276 a + 2.577 a^2)
                            for a = 1/sqrt(t) < 1.6, else 1

    (the Beckmann one is Walter et al.'s rational approximation, < 0.35 %
    from the exact ``2 / (1 + erf(a) + exp(-a^2)/(a sqrt(pi)))``, and it is
    Mitsuba's); both 1 when ``t = 0`` and 0 when ``dot(v, m) v.z <= 0``.
    ``G(wi, wo, m) = G1(wi, m) G1(wo, m)`` (separable, as Mitsuba).

    Sampling. Visible normals (:meth:`sample_visible`, density
    :meth:`pdf_visible` ``= D_wi(m) = G1(wi, m) |dot(wi, m)| D(m) / wi.z``,
    0 for ``wi.z <= 0``): stretch ``wi`` to ``wi' = normalize(au wi.x, av
    wi.y, wi.z)``, sample the visible slopes of the ``alpha = 1``
    distribution for ``cos theta' = wi'.z`` (azimuth 0), rotate them to
    ``wi'``'s azimuth, scale by ``(au, av)`` and take ``m = normalize(-x,
    -y, 1)``. The ``alpha = 1`` slopes: GGX -- Heitz 2018 on a concentric
    disk (the point's hemisphere normal is used directly, not divided into
    slopes, so a horizontal normal stays finite); Beckmann -- Jakob 2014,
    "An Improved Visible Normal Sampling Routine for the Beckmann
    Distribution": the inverse CDF of the slope solved in the erf domain
    from Jakob's initial guess, the second slope ``erfinv(2 u.y - 1)``, ``u``
    clamped to ``[1e-6, 1 - 1e-6]`` as Mitsuba; drpt takes three *Halley*
    steps where Mitsuba takes three Newton steps (the second derivative is
    a by-product of the first), which keeps the sampled CDF within 5e-7 of
    ``u`` (near the float32 floor; asserted by tests/render/bsdf/test_microfacet.py)
    where Newton's converge slowly (``cos theta'`` 0.8-0.95, ``u`` near 1, where the
    CDF flattens; the errors measured: docs/performance.md, "Beckmann's sampler"),
    and evaluates ``erf``,
    ``erfinv``, ``exp`` and ``log`` by :mod:`drpt.render.erf32` (the last
    ``erfinv``, after the third step, by Taylor's second order from the
    second's). With the
    same ``u`` GGX's normal is Mitsuba's (to float rounding) except where
    ``wi'`` is within ~1e-3 rad of the normal: there Mitsuba's azimuth of
    ``wi'`` (from ``sin^2 theta = 1 - cos^2 theta`` in float32) is inexact,
    drpt's (from ``wi'.x, wi'.y``) is not; Beckmann's is Mitsuba's up to the
    accuracy of Mitsuba's three Newton steps as well. With ``sample_visible = False``
    (:meth:`sample_all`, density :meth:`pdf_all` ``= D(m) m.z``): the
    azimuth ``phi = 2 pi u.y`` (anisotropic: ``tan phi = (av/au) tan(2 pi
    u.y)`` in the quadrant of ``2 pi u.y``, with ``alpha^2 = 1 / (cos^2
    phi / au^2 + sin^2 phi / av^2)``), and ``cos theta = 1/sqrt(1 - alpha^2
    log(1 - u.x))`` (Beckmann) or ``tan^2 theta = alpha^2 u.x / (1 -
    u.x)`` (GGX); ``sin theta = tan theta cos theta`` (Mitsuba's ``sqrt(1 -
    cos^2 theta)`` loses the small angles of small alphas to float32).
    The density returned with a sample is :meth:`pdf` at that normal (not
    Mitsuba's closed form in ``u``), so it is exactly what :meth:`pdf`
    gives for the same normal.
    """

    def __init__(self, beckmann, alpha_u, alpha_v=None, sample_visible: bool = True,
                 alpha_min: float = ALPHA_MIN):
        self.beckmann = beckmann
        self.isotropic = alpha_v is None
        self.alpha_u = dr.maximum(Float(alpha_u), alpha_min)
        self.alpha_v = self.alpha_u if self.isotropic else dr.maximum(Float(alpha_v), alpha_min)
        self.sample_visible = bool(sample_visible)

    def _pick(self, beck, ggx):
        """``beck()`` or ``ggx()`` (thunks), traced only as needed."""
        if isinstance(self.beckmann, bool):
            return beck() if self.beckmann else ggx()
        return dr.select(self.beckmann, beck(), ggx())

    # -- the distribution -------------------------------------------------
    def D(self, m: Array3f) -> Float:
        """Normal distribution (density over the solid angle of ``m``, projected-area normalized)."""
        au, av = self.alpha_u, self.alpha_v
        c2 = dr.square(m.z)
        s = dr.square(m.x / au) + dr.square(m.y / av)

        def beck():
            return dr.exp(-s / c2) / (dr.pi * au * av * dr.square(c2))

        def ggx():
            return dr.rcp(dr.pi * au * av * dr.square(s + c2))

        d = self._pick(beck, ggx)
        return dr.select(d * m.z > 1e-20, d, 0.0)

    def G1(self, v: Array3f, m: Array3f) -> Float:
        """Smith's masking for direction ``v`` on microfacet ``m``."""
        xy = dr.square(self.alpha_u * v.x) + dr.square(self.alpha_v * v.y)
        t = xy / dr.square(v.z)  # +inf for v.z = 0

        def beck():
            a = dr.rsqrt(t)
            a2 = dr.square(a)
            r = (3.535 * a + 2.181 * a2) / (1.0 + 2.276 * a + 2.577 * a2)
            return dr.select(a >= 1.6, 1.0, r)

        def ggx():
            return 2.0 / (1.0 + dr.sqrt(1.0 + t))

        g = self._pick(beck, ggx)
        g = dr.select(xy == 0.0, 1.0, g)
        return dr.select(dr.dot(v, m) * v.z <= 0.0, 0.0, g)

    def G(self, wi: Array3f, wo: Array3f, m: Array3f) -> Float:
        """Separable Smith shadowing-masking ``G1(wi, m) G1(wo, m)``."""
        return self.G1(wi, m) * self.G1(wo, m)

    # -- densities --------------------------------------------------------
    def pdf_visible(self, wi: Array3f, m: Array3f) -> Float:
        """``D_wi(m) = G1(wi, m) |dot(wi, m)| D(m) / wi.z``; 0 for ``wi.z <= 0``."""
        ok = wi.z > 0.0
        v = self.D(m) * self.G1(wi, m) * dr.abs(dr.dot(wi, m)) / dr.select(ok, wi.z, 1.0)
        return dr.select(ok, v, 0.0)

    def pdf_all(self, m: Array3f) -> Float:
        """``D(m) m.z``: the density of :meth:`sample_all`."""
        return self.D(m) * m.z

    def pdf(self, wi: Array3f, m: Array3f) -> Float:
        """Density of :meth:`sample` (visible or all normals, per ``sample_visible``)."""
        return self.pdf_visible(wi, m) if self.sample_visible else self.pdf_all(m)

    # -- sampling ---------------------------------------------------------
    def sample(self, wi: Array3f, u: Array2f) -> tuple[Array3f, Float]:
        """A normal and its density, per ``sample_visible`` (Mitsuba's ``sample``)."""
        m = self.sample_visible_normal(wi, u) if self.sample_visible else self.sample_all(u)
        return m, self.pdf(wi, m)

    def _slopes11_ggx(self, cos_i: Float, u: Array2f, disk: Array2f | None = None) -> Array3f:
        """Visible normal of the alpha = 1 GGX for ``wi = (sin_i, 0, cos_i)``; ``disk``:
        ``u``'s point of :func:`~drpt.render.warp.square_to_uniform_disk_concentric`, when
        the caller has it."""
        p = square_to_uniform_disk_concentric(u) if disk is None else disk
        s = 0.5 * (1.0 + cos_i)
        py = (1.0 - s) * dr.safe_sqrt(1.0 - dr.square(p.x)) + s * p.y
        z = dr.safe_sqrt(1.0 - dr.square(p.x) - dr.square(py))
        sin_i = dr.safe_sqrt(1.0 - dr.square(cos_i))
        # hemisphere point in the basis (t1, t2, wi) = ((0,-1,0), (-cos_i,0,sin_i), (sin_i,0,cos_i)),
        # its y negated (see sample_visible_normal)
        return Array3f(sin_i * z - cos_i * py, p.x, sin_i * py + cos_i * z)

    def _slopes11_beckmann(self, cos_i: Float, u: Array2f) -> Array3f:
        """Visible normal of the alpha = 1 Beckmann for ``wi = (sin_i, 0, cos_i)`` (Jakob 2014),
        with :mod:`drpt.render.erf32`'s ``erf``, ``erfinv``, ``exp`` and ``log``. ``cos_i`` is
        clamped to ``>= 1e-12`` (below about 1e-23 the Halley step's products overflow float32; the
        slope distribution's change from ``cos_i`` to 0 is of the order of ``cos_i``)."""
        cos_i = dr.maximum(cos_i, 1e-12)
        tan_i = dr.safe_sqrt(1.0 - dr.square(cos_i)) / cos_i
        cot_i = dr.rcp(tan_i)
        maxval = erf32.erf(cot_i)
        ux = dr.clip(u.x, 1e-6, 1.0 - 1e-6)
        uy = dr.clip(u.y, 1e-6, 1.0 - 1e-6)
        isp = 1.0 / dr.sqrt(dr.pi)
        x = maxval - (maxval + 1.0) * erf32.erf(dr.sqrt(-erf32.log(ux)))
        ux = ux * (1.0 + maxval + isp * tan_i * erf32.exp(-dr.square(cot_i)))
        for _ in range(_HALLEY_STEPS):
            # Halley's step on g(x) = 1 + x + isp tan_i e^(-slope^2) - ux, slope = erfinv(x):
            # g' = 1 - slope tan_i, g'' = -tan_i (sqrt(pi) / 2) e^(slope^2); x -= 2 g g' / (2 g'^2 - g g''),
            # numerator and denominator times e^(-slope^2) (finite for |slope| < 9); the denominator
            # kept >= g'^2 e (a step at most twice Newton's, never through a pole)
            xc = dr.clip(x, -_ERF_MAX, _ERF_MAX)
            slope = erf32.erfinv(xc)
            e = erf32.exp(-dr.square(slope))
            g = 1.0 + x + isp * tan_i * e - ux
            g1 = 1.0 - slope * tan_i
            g1e = dr.square(g1) * e
            x = x - 2.0 * g * g1 * e / dr.maximum(2.0 * g1e + (0.5 * dr.sqrt(dr.pi)) * tan_i * g, g1e)
        # erfinv at the last step's x from the one before it by Taylor's second order (the step
        # is at the CDF's 1e-5 by then): erfinv' = k = (sqrt(pi) / 2) e^(slope^2), erfinv'' = 2 slope k^2
        kd = (0.5 * dr.sqrt(dr.pi)) / e * (dr.clip(x, -_ERF_MAX, _ERF_MAX) - xc)
        sx = slope + kd + slope * dr.square(kd)
        sy = erf32.erfinv(2.0 * uy - 1.0)
        return Array3f(-sx, sy, 1.0)  # (y negated, see sample_visible_normal)

    def sample_visible_normal(self, wi: Array3f, u: Array2f, disk: Array2f | None = None) -> Array3f:
        """A normal visible from ``wi`` (``wi.z > 0``), density :meth:`pdf_visible`.
        ``disk`` (GGX only): ``r (cos phi, sin phi)`` of
        :func:`drpt.render.warp.concentric_polar` at ``u``,
        computed by the caller (the same normal, to the float; a lobe choosing between
        this and another warp of ``u`` per lane then takes one ``sincos``)."""
        if disk is not None and self.beckmann is not False:
            raise ValueError("sample_visible_normal: disk is for GGX only")
        au, av = self.alpha_u, self.alpha_v
        wp = dr.normalize(Array3f(au * wi.x, av * wi.y, wi.z))
        # azimuth of wp from its x, y (Mitsuba takes sin^2 theta = 1 - z^2, which
        # cancels catastrophically near the pole; this is the accurate value)
        r2 = dr.square(wp.x) + dr.square(wp.y)
        inv = dr.rsqrt(dr.select(r2 > 0.0, r2, 1.0))
        cphi = dr.select(r2 > 0.0, wp.x * inv, 1.0)
        sphi = dr.select(r2 > 0.0, wp.y * inv, 0.0)
        n = self._pick(lambda: self._slopes11_beckmann(wp.z, u), lambda: self._slopes11_ggx(wp.z, u, disk))
        # rotate to wi's azimuth, unstretch (the _slopes11 functions return the normal
        # with y negated: the rotation then needs no negation, to the same floats)
        nx = cphi * n.x + sphi * n.y
        ny = sphi * n.x - cphi * n.y
        return dr.normalize(Array3f(au * nx, av * ny, dr.maximum(n.z, 0.0)))

    def sample_all(self, u: Array2f) -> Array3f:
        """A normal drawn from ``D(m) m.z`` (``sample_visible = False``)."""
        au, av = self.alpha_u, self.alpha_v
        if self.isotropic:
            sphi, cphi = dr.sincos(2.0 * dr.pi * u.y)
            a2 = dr.square(au)
        else:
            tmp = (av / au) * dr.tan(2.0 * dr.pi * u.y)
            cphi = dr.rsqrt(tmp * tmp + 1.0)
            cphi = dr.mulsign(cphi, dr.abs(u.y - 0.5) - 0.25)
            sphi = cphi * tmp
            ok = dr.isfinite(sphi)
            cphi, sphi = dr.select(ok, cphi, 0.0), dr.select(ok, sphi, dr.sign(tmp))
            a2 = dr.rcp(dr.square(cphi / au) + dr.square(sphi / av))

        def beck():
            return -a2 * dr.log(1.0 - u.x)

        def ggx():
            return a2 * u.x / (1.0 - u.x)

        tan2 = self._pick(beck, ggx)
        # sin from tan (not sqrt(1 - cos^2), which float32 quantizes near the pole)
        c = dr.rsqrt(1.0 + tan2)
        s = dr.select(dr.isinf(tan2), 1.0, dr.sqrt(tan2) * c)
        return Array3f(cphi * s, sphi * s, c)
