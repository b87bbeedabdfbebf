"""Smooth dielectric (glass): Fresnel-weighted choice of perfect reflection
or refraction. Matches Mitsuba 3's ``dielectric`` plugin (``int_ior = eta``,
``ext_ior = 1``) sample for sample.

Frame and sides
---------------
Unlike the reflective lobes this one sees the *unflipped* shading frame:
``+z`` is the shading normal and points to the outside (vacuum, IOR 1).
``wi.z >= 0`` means the viewer is outside (``wi.z == 0`` counts as outside,
as in Mitsuba), ``wi.z < 0`` inside the medium of IOR ``eta``.

Fresnel
-------
:func:`fresnel_dielectric` is the exact unpolarized reflectance
``F = (r_s^2 + r_p^2) / 2`` with amplitudes

    r_s = (cos_i - eta_it cos_t) / (cos_i + eta_it cos_t)
    r_p = (cos_t - eta_it cos_i) / (cos_t + eta_it cos_i)

(absolute cosines, ``eta_it`` = IOR on the far side / IOR on the viewer's
side). Total internal reflection (``sin_t^2 >= 1``) gives ``cos_t = 0`` and
``F = 1``; ``eta == 1`` gives ``F = 0`` (pure pass-through, also at grazing
incidence); ``cos_i == 0`` with ``eta != 1`` gives ``F = 1``.

Sampling and weights
--------------------
With ``u1 <= F`` the lobe reflects (``wo = (-wi.x, -wi.y, wi.z)``, weight 1),
else it refracts (``wo = (-eta_ti wi.x, -eta_ti wi.y, cos_t)``, ``cos_t`` of
the opposite sign to ``wi.z``, by Snell's law) with weight ``eta_ti^2 =
1 / eta_it^2``. That factor is the radiance scaling across the interface:
radiance is ``n^2``-compressed/expanded along a refracted ray, so radiance
arriving in the viewer's medium from the far side is ``(n_viewer / n_far)^2``
times the far-side radiance, i.e. ``eta_ti^2``. It is exactly what Mitsuba's
``dielectric`` applies in ``TransportMode::Radiance`` (``weight *=
sqr(eta_ti)`` on transmission). The Fresnel factor cancels against the
selection probability, so reflection weighs 1 and refraction ``eta_ti^2``.
``BSDFSample.eta`` is ``eta_it`` for refraction and 1 for reflection (as
Mitsuba's ``bs.eta``): the path's product of these times ``beta`` undoes the
``eta_ti^2`` factors for Russian roulette. ``pdf`` is 0 and ``delta`` is
True (a Dirac lobe); ``eval`` and ``pdf`` are 0.
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array2f, Array3f, Bool, Float

from . import BSDFSample

#: Spec fields the material table uploads for this lobe (see :class:`drpt.render.bsdf.BSDF`).
FIELDS = {"eta": "float"}


def derive(params: dict) -> dict:
    """``eta = int_ior / ext_ior`` (host side)."""
    int_ior, ext_ior = float(params["int_ior"]), float(params["ext_ior"])
    if not (int_ior > 0.0 and ext_ior > 0.0):
        raise ValueError(f"dielectric: indices of refraction must be positive, got {int_ior:g}, {ext_ior:g}")
    return {"eta": int_ior / ext_ior}
DELTA = True


class DielectricParams:
    """``eta``: interior IOR over exterior IOR (exterior = vacuum, so the IOR)."""

    DRJIT_STRUCT = {"eta": Float}

    def __init__(self, eta=None):
        self.eta = eta if eta is not None else Float(1.5)


def params(table, si, active) -> DielectricParams:
    """The parameters of the lanes' materials, gathered from the material table."""
    return DielectricParams(table.value("eta", si, active))


def fresnel_dielectric(cos_i: Float, eta: Float):
    """Unpolarized Fresnel reflectance of a smooth dielectric interface.

    ``cos_i``: cosine between the incident direction and the normal (signed:
    ``>= 0`` on the outside); ``eta``: interior over exterior IOR.
    Returns ``(F, cos_t, eta_it, eta_ti)``: reflectance, the *signed* cosine
    of the refracted direction (opposite sign to ``cos_i``, 0 under total
    internal reflection), the relative IOR in the direction of travel (far
    side over near side) and its reciprocal.
    """
    cos_i = Float(cos_i)
    eta = Float(eta)
    outside = cos_i >= 0.0
    rcp_eta = dr.rcp(eta)
    eta_it = dr.select(outside, eta, rcp_eta)
    eta_ti = dr.select(outside, rcp_eta, eta)

    # Snell: sin_t^2 = eta_ti^2 sin_i^2, so cos_t^2 = 1 - eta_ti^2 + eta_ti^2 cos_i^2
    # (< 0 under TIR). Written this way (not 1 - eta_ti^2 (1 - cos_i^2), as Mitsuba
    # does) it keeps full precision near grazing incidence when eta_ti ~ 1: with
    # eta = 1 it gives cos_t = |cos_i| exactly, so the ray passes straight through.
    eti2 = eta_ti * eta_ti
    cos_t2 = dr.fma(eti2, cos_i * cos_i, 1.0 - eti2)
    ci = dr.abs(cos_i)
    ct = dr.safe_sqrt(cos_t2)

    r_s = dr.fma(-eta_it, ct, ci) / dr.fma(eta_it, ct, ci)
    r_p = dr.fma(-eta_it, ci, ct) / dr.fma(eta_it, ci, ct)
    f = 0.5 * (dr.square(r_s) + dr.square(r_p))

    # 0/0 cases: index matched (F = 0 everywhere) and grazing incidence (F = 1).
    matched = eta == 1.0
    f = dr.select(matched, 0.0, dr.select(ci == 0.0, 1.0, f))
    f = dr.clip(f, 0.0, 1.0)
    cos_t = dr.select(outside, -ct, ct)
    return f, cos_t, eta_it, eta_ti


def eval(p: DielectricParams, wi: Array3f, wo: Array3f) -> Array3f:
    return Array3f(0.0)


def pdf(p: DielectricParams, wi: Array3f, wo: Array3f) -> Float:
    return dr.zeros(Float, dr.width(wi))


def sample(p: DielectricParams, wi: Array3f, u1: Float, u2: Array2f) -> BSDFSample:
    f, cos_t, eta_it, eta_ti = fresnel_dielectric(wi.z, p.eta)
    refl = u1 <= f
    wo_r = Array3f(-wi.x, -wi.y, wi.z)
    wo_t = Array3f(-eta_ti * wi.x, -eta_ti * wi.y, cos_t)
    wo = dr.select(refl, wo_r, wo_t)
    w = dr.select(refl, 1.0, dr.square(eta_ti))
    n = dr.width(wi)
    return BSDFSample(wo, Array3f(w), dr.zeros(Float, n), dr.full(Bool, True, n),
                      dr.full(Bool, True, n), dr.select(refl, 1.0, eta_it))
