"""Host-side (numpy) precomputation of ``roughplastic``'s coating tables,
by the quadrature of Mitsuba 3 (``include/mitsuba/render/microfacet.h``:
``eval_transmittance``, ``eval_reflectance``; ``src/bsdfs/roughplastic.cpp``:
``parameters_changed``). No Dr.Jit: :func:`drpt.render.bsdf.roughplastic.derive`
calls it once per material.

What is computed
----------------
For a rough dielectric interface of relative IOR ``eta`` (far side over the
side of ``wi``) with microfacet distribution ``D`` (Beckmann or GGX,
isotropic ``alpha``, clamped to >= 1e-4 as Mitsuba does) and Smith's
``G1``, with ``m`` drawn from the distribution of normals visible from
``wi`` (``D_wi``, always, whatever the plugin's ``sample_visible``):

* transmittance ``T(wi) = E_m[ G1(wo_t, m) (1 - F(wi.m)) ]``, ``wo_t`` the
  refraction of ``wi`` about ``m`` (0 where it stays on ``wi``'s side);
* reflectance ``R(wi) = E_m[ G1(wo_r, m) F(wi.m) ]``, ``wo_r`` the
  reflection (0 where it goes below the surface).

Each expectation is the integral over the unit square of the VNDF sampler's
sample (``m = sample(wi, u)``), by an ``n x n`` tensor Gauss-Legendre rule
(nodes mapped from [-1, 1] to [0, 1], weights times 1/4), with ``n = 32``
when ``eta > 1`` and ``n = 128`` otherwise -- Mitsuba's choice. The sampler
is Mitsuba's, transcribed: for GGX the Heitz 2018 slope-space sampler on a
*concentric* disk (``square_to_uniform_disk_concentric``); for Beckmann
Jakob's numerical inversion (three Newton steps in the erf domain, samples
clamped to [1e-6, 1 - 1e-6]), with Dr.Jit's ``erfinv`` (Giles'
single-precision approximation) and ``math.erf``. The same rule on the same
integrand gives Mitsuba's numbers (to float32 rounding: Mitsuba sums in
float32, this in float64).

The tables
----------
``mu_i = max(1e-6, i / (N - 1))``, ``i = 0 .. N-1``, ``N = RES = 64``
(``MI_ROUGH_TRANSMITTANCE_RES``), ``wi = (sqrt(1 - mu^2), 0, mu)``:

* ``external_transmittance[i] = T(wi_i; eta)`` -- the table roughplastic
  interpolates linearly at ``cos theta`` (samples at ``x = i / (N - 1)``);
* ``internal_reflectance = 2 mean_i( R(wi_i; 1 / eta) mu_i )`` -- a scalar:
  Mitsuba's (crude, equal-weight) estimate of the hemispherical average of
  the reflectance seen from inside the coating, used as ``2 int R mu dmu``.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

#: Mitsuba's ``MI_ROUGH_TRANSMITTANCE_RES``: samples of the transmittance table.
RES = 64
#: Mitsuba's lower bound on microfacet alphas (``MicrofacetDistribution::configure``).
ALPHA_MIN = 1e-4

_INV_SQRT_PI = 1.0 / math.sqrt(math.pi)
_erf = np.vectorize(math.erf, otypes=[np.float64])


_ERFINV_C1 = (1.50140941, 0.246640727, -0.00417768164, -0.00125372503, 0.00021858087,
              -4.39150654e-06, -3.5233877e-06, 3.43273939e-07, 2.81022636e-08)
_ERFINV_C2 = (2.83297682, 1.00167406, 0.00943887047, -0.0076224613, 0.00573950773,
              -0.00367342844, 0.00134934322, 0.000100950558, -0.000200214257)


def _horner(x, c):
    r = np.full_like(x, c[-1])
    for k in reversed(c[:-1]):
        r *= x
        r += k
    return r


def erfinv(x: np.ndarray) -> np.ndarray:
    """Dr.Jit's ``erfinv``: M. Giles, "Approximating the erfinv function"
    (GPU Computing Gems, 2011), the single-precision fit."""
    x = np.asarray(x, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        w = -np.log((1.0 - x) * (1.0 + x))
        p = _horner(w - 2.5, _ERFINV_C1)
        tail = ~(w < 5.0)
        if tail.any():
            p[tail] = _horner(np.sqrt(w[tail]) - 3.0, _ERFINV_C2)
    return p * x


def fresnel(cos_i: np.ndarray, eta: float):
    """Mitsuba's ``fresnel`` (exact unpolarized dielectric reflectance):
    ``(F, cos_t, eta_it, eta_ti)``, ``cos_t`` signed opposite to ``cos_i``."""
    outside = cos_i >= 0.0
    eta_it = np.where(outside, eta, 1.0 / eta)
    eta_ti = np.where(outside, 1.0 / eta, eta)
    cos_t2 = 1.0 - (1.0 - cos_i * cos_i) * eta_ti * eta_ti
    ci = np.abs(cos_i)
    ct = np.sqrt(np.maximum(cos_t2, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        a_s = (ci - eta_it * ct) / (ci + eta_it * ct)
        a_p = (ct - eta_it * ci) / (ct + eta_it * ci)
    r = 0.5 * (a_s * a_s + a_p * a_p)
    special = (eta == 1.0) | (ci == 0.0)
    r = np.where(special, 0.0 if eta == 1.0 else 1.0, r)
    return r, np.where(outside, -ct, ct), eta_it, eta_ti


def smith_g1(beckmann: bool, alpha: float, v, m) -> np.ndarray:
    """Mitsuba's ``smith_g1`` (isotropic): GGX exact, Beckmann by its rational fit."""
    vx, vy, vz = v
    xy = (alpha * vx) ** 2 + (alpha * vy) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        tan2 = xy / (vz * vz)
        if beckmann:
            a = 1.0 / np.sqrt(tan2)
            g = np.where(a >= 1.6, 1.0, (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a))
        else:
            g = 2.0 / (1.0 + np.sqrt(1.0 + tan2))
    g = np.where(xy == 0.0, 1.0, g)
    dot = vx * m[0] + vy * m[1] + vz * m[2]
    return np.where(dot * vz <= 0.0, 0.0, g)


def _disk_concentric(u1, u2):
    x = 2.0 * u1 - 1.0
    y = 2.0 * u2 - 1.0
    q13 = np.abs(x) < np.abs(y)
    r = np.where(q13, y, x)
    rp = np.where(q13, x, y)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = 0.25 * np.pi * rp / r
    phi = np.where(q13, 0.5 * np.pi - phi, phi)
    phi = np.where((x == 0.0) & (y == 0.0), 0.0, phi)
    return r * np.cos(phi), r * np.sin(phi)


def _slopes_11(beckmann: bool, cos_i, u1, u2):
    """Mitsuba's ``sample_visible_11``: slopes of a visible normal for alpha = 1."""
    if beckmann:
        with np.errstate(divide="ignore"):
            tan_i = np.sqrt(np.maximum(1.0 - cos_i * cos_i, 0.0)) / cos_i
            cot_i = 1.0 / tan_i
        maxval = _erf(cot_i)
        u1 = np.clip(u1, 1e-6, 1.0 - 1e-6)
        u2 = np.clip(u2, 1e-6, 1.0 - 1e-6)
        x = maxval - (maxval + 1.0) * _erf(np.sqrt(-np.log(u1)))
        tail = _INV_SQRT_PI * tan_i * np.exp(-cot_i * cot_i)
        u1 = u1 * (1.0 + maxval + tail)
        for _ in range(3):
            slope = erfinv(x)
            value = 1.0 + x + _INV_SQRT_PI * tan_i * np.exp(-slope * slope) - u1
            x = x - value / (1.0 - slope * tan_i)
        return erfinv(x), erfinv(2.0 * u2 - 1.0) + 0.0 * x
    px, py = _disk_concentric(u1, u2)
    s = 0.5 * (1.0 + cos_i)
    py = (1.0 - s) * np.sqrt(np.maximum(1.0 - px * px, 0.0)) + s * py
    z = np.sqrt(np.maximum(1.0 - px * px - py * py, 0.0))
    sin_i = np.sqrt(np.maximum(1.0 - cos_i * cos_i, 0.0))
    norm = 1.0 / (sin_i * py + cos_i * z)
    return (cos_i * py - sin_i * z) * norm, px * norm


def sample_visible(beckmann: bool, alpha: float, mu: np.ndarray, u1: np.ndarray, u2: np.ndarray):
    """Visible normals ``m`` for ``wi = (sqrt(1 - mu^2), 0, mu)`` (``mu`` of
    shape (M, 1), samples of shape (K,)): arrays (3, M, K)."""
    wx, wz = alpha * np.sqrt(1.0 - mu * mu), mu
    cos_p = wz / np.sqrt(wx * wx + wz * wz)  # stretched wi; its phi is 0 (wi.y = 0)
    sx, sy = _slopes_11(beckmann, cos_p, u1, u2)
    mx, my = -alpha * sx, -alpha * sy
    n = np.sqrt(mx * mx + my * my + 1.0)
    return np.stack(np.broadcast_arrays(mx / n, my / n, 1.0 / n))


def _quadrature(eta: float):
    n = 32 if eta > 1.0 else 128
    x, w = np.polynomial.legendre.leggauss(n)
    xx, yy = np.meshgrid(x, x)
    wx, wy = np.meshgrid(w, w)
    return 0.5 * xx.ravel() + 0.5, 0.5 * yy.ravel() + 0.5, 0.25 * (wx * wy).ravel()


def _wi(mu):
    mu = np.asarray(mu, np.float64).reshape(-1, 1)
    return mu, np.sqrt(np.maximum(1.0 - mu * mu, 0.0))


def transmittance(beckmann: bool, alpha: float, eta: float, mu) -> np.ndarray:
    """Mitsuba's ``eval_transmittance`` at ``wi = (sqrt(1 - mu^2), 0, mu)``."""
    alpha = max(float(alpha), ALPHA_MIN)
    mu, sx = _wi(mu)
    u1, u2, w = _quadrature(eta)
    m = sample_visible(beckmann, alpha, mu, u1, u2)
    dot = sx * m[0] + mu * m[2]
    f, cos_t, _, eta_ti = fresnel(dot, eta)
    k = dot * eta_ti + cos_t
    wo = (m[0] * k - sx * eta_ti, m[1] * k, m[2] * k - mu * eta_ti)
    g = smith_g1(beckmann, alpha, wo, m) * (1.0 - f)
    g = np.where(wo[2] * mu >= 0.0, 0.0, g)
    return g @ w


def reflectance(beckmann: bool, alpha: float, eta: float, mu) -> np.ndarray:
    """Mitsuba's ``eval_reflectance`` at ``wi = (sqrt(1 - mu^2), 0, mu)``."""
    alpha = max(float(alpha), ALPHA_MIN)
    mu, sx = _wi(mu)
    u1, u2, w = _quadrature(eta)
    m = sample_visible(beckmann, alpha, mu, u1, u2)
    dot = sx * m[0] + mu * m[2]
    wo = (2.0 * dot * m[0] - sx, 2.0 * dot * m[1], 2.0 * dot * m[2] - mu)
    f = fresnel(dot, eta)[0]
    g = smith_g1(beckmann, alpha, wo, m) * f
    g = np.where((wo[2] <= 0.0) | (mu <= 0.0), 0.0, g)
    return g @ w


def table_mu() -> np.ndarray:
    """The table's cosines: ``max(1e-6, linspace(0, 1, RES))``."""
    return np.maximum(1e-6, np.linspace(0.0, 1.0, RES))


@lru_cache(maxsize=256)
def coating_tables(beckmann: bool, alpha: float, eta: float) -> tuple[np.ndarray, float]:
    """``(external_transmittance (RES,), internal_reflectance)`` of a coating."""
    mu = table_mu()
    t = transmittance(beckmann, alpha, eta, mu)
    r = float(np.mean(reflectance(beckmann, alpha, 1.0 / eta, mu) * mu) * 2.0)
    t.setflags(write=False)
    return t, r
