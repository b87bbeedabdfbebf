"""Smooth dielectric (glass): Fresnel-weighted choice of perfect reflection
or refraction. Mitsuba 3's ``dielectric`` plugin, sample for sample.

Parameters (Mitsuba's names and defaults, :data:`drpt.materials.bsdf_kinds.PARAMS`)
-----------------------------------------------------------------------
``int_ior`` (default ``"bk7"`` = 1.5046), ``ext_ior`` (default ``"air"`` =
1.000277): numbers or the medium names of :mod:`drpt.materials.iors`; the lobe uses
``eta = int_ior / ext_ior`` only (:func:`derive`, computed in float32 as
Mitsuba does; ``eta < 1`` is allowed: e.g. an air bubble in water).
``specular_reflectance``, ``specular_transmittance`` (RGB or texture,
default 1): tints that multiply the reflected and the refracted weight.
They are not physically meaningful (Mitsuba's words) but Mitsuba has them.

Frame and sides
---------------
Unlike the reflective lobes this one sees the *unflipped* shading frame:
``+z`` is the shading normal and points to the exterior (IOR ``ext_ior``).
``wi.z >= 0`` means the viewer is outside (``wi.z == 0`` counts as outside,
as in Mitsuba), ``wi.z < 0`` inside the medium.

Fresnel
-------
:func:`fresnel_dielectric` is the exact unpolarized reflectance
``F = (r_s^2 + r_p^2) / 2`` with amplitudes

    r_s = (cos_i - eta_it cos_t) / (cos_i + eta_it cos_t)
    r_p = (cos_t - eta_it cos_i) / (cos_t + eta_it cos_i)

(absolute cosines, ``eta_it`` = IOR on the far side / IOR on the viewer's
side). Total internal reflection (``sin_t^2 >= 1``) gives ``cos_t = 0`` and
``F = 1``; ``eta == 1`` gives ``F = 0`` (pure pass-through, also at grazing
incidence); ``cos_i == 0`` with ``eta != 1`` gives ``F = 1``. Same function
as Mitsuba's ``fresnel()`` (``fresnel.h``) except that ``cos_t^2`` is
computed as ``1 - eta_ti^2 + eta_ti^2 cos_i^2`` (see the code): equal in
exact arithmetic, more accurate near grazing incidence when ``eta ~ 1``.

Sampling and weights
--------------------
With ``u1 <= F`` the lobe reflects (``wo = (-wi.x, -wi.y, wi.z)``, weight
``specular_reflectance``), else it refracts (``wo = (-eta_ti wi.x, -eta_ti
wi.y, cos_t)``, ``cos_t`` of the opposite sign to ``wi.z``, by Snell's law)
with weight ``specular_transmittance * eta_ti^2`` (``eta_ti = 1 /
eta_it``). The Fresnel factor cancels against the selection probability.
``eta_ti^2`` is the radiance scaling across the interface: radiance is
``n^2``-compressed/expanded along a refracted ray, so radiance arriving in
the viewer's medium from the far side is ``(n_viewer / n_far)^2`` times the
far-side radiance; it is what Mitsuba's ``dielectric`` applies in
``TransportMode::Radiance`` (``weight *= sqr(eta_ti)`` on transmission).
``BSDFSample.eta`` is ``eta_it`` for refraction and 1 for reflection (as
Mitsuba's ``bs.eta``): the path's product of these times ``beta`` undoes the
``eta_ti^2`` factors for Russian roulette. ``pdf`` is 0 and ``delta`` is
True (a Dirac lobe; Mitsuba reports the discrete probability ``F`` or
``1 - F`` as ``bs.pdf``, drpt's delta lobes report 0); ``eval`` and ``pdf``
are 0.
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array2f, Array3f, Bool, Float

from ...materials.iors import relative_ior
from . import BSDFSample

#: Per-material values the material table uploads (see :mod:`drpt.render.bsdf`):
#: ``rel_ior`` from :func:`derive`, the tints from the spec's parameters.
FIELDS = {"rel_ior": "float", "specular_reflectance": "rgb", "specular_transmittance": "rgb"}
DELTA = True


def derive(params: dict) -> dict:
    """``rel_ior = int_ior / ext_ior`` (names resolved by :mod:`drpt.materials.iors`).
    ``ValueError`` for an unknown name or an IOR that is not finite and > 0."""
    return {"rel_ior": relative_ior(params["int_ior"], params["ext_ior"])}


class DielectricParams:
    """``eta``: interior over exterior IOR; ``r``, ``t``: the reflection and
    transmission tints (``specular_reflectance``, ``specular_transmittance``)."""

    DRJIT_STRUCT = {"eta": Float, "r": Array3f, "t": Array3f}

    def __init__(self, eta=None, r=None, t=None):
        self.eta = eta if eta is not None else Float(1.5046)
        self.r = r if r is not None else Array3f(1.0)
        self.t = t if t is not None else Array3f(1.0)


def _is_white(v) -> bool:
    """A parameter value that is the constant 1 (so a tint need not be gathered)."""
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return float(v) == 1.0
    if isinstance(v, (tuple, list)) and len(v) == 3:
        return all(isinstance(x, (int, float)) and float(x) == 1.0 for x in v)
    return False


def tint(table, kind: str, name: str, si, active) -> Array3f:
    """Tint ``name`` of the lanes' materials; the constant 1 (nothing gathered,
    nothing traced) when every ``kind`` spec of the scene leaves it at 1."""
    specs = table.specs_of(kind)
    if specs and all(_is_white(s.params.get(name, 1.0)) for s in specs):
        return Array3f(1.0)
    return table.value(name, si, active)


def params(table, si, active) -> DielectricParams:
    """The parameters of the lanes' materials, gathered from the material table."""
    return DielectricParams(table.value("rel_ior", si, active),
                            tint(table, "dielectric", "specular_reflectance", si, active),
                            tint(table, "dielectric", "specular_transmittance", si, active))



def transmission_importance(eta: Float, wi: Array3f, wo: Array3f) -> Float:
    """The factor from a rough interface's radiance-mode value (its transmission scaled by
    ``1 / eta_i^2``) to importance mode's (a light subpath's vertex: Mitsuba's
    ``TransportMode::Importance``): ``eta_i^2`` where ``wi`` and ``wo`` lie on opposite sides
    (``eta_i`` the IOR ratio ``eta`` seen from ``wi``'s side), else 1."""
    eta_i = dr.select(wi.z > 0.0, eta, dr.rcp(eta))
    return dr.select(wi.z * wo.z < 0.0, dr.square(eta_i), 1.0)

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
    w = dr.select(refl, p.r, p.t * dr.square(eta_ti))
    n = dr.width(wi)
    return BSDFSample(wo, Array3f(w), dr.zeros(Float, n), dr.full(Bool, True, n),
                      dr.full(Bool, True, n), dr.select(refl, 1.0, eta_it))
