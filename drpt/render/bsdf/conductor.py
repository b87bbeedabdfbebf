"""Smooth conductor: Mitsuba 3's ``conductor`` plugin (``src/bsdfs/conductor.cpp``).

A Dirac lobe: perfect specular reflection ``wo = (-wi.x, -wi.y, wi.z)``
weighted by the unpolarized Fresnel reflectance of a conductor with complex
IOR ``eta + i k`` (per RGB channel) and by ``specular_reflectance``::

    sample weight = F_c(cos_i; eta, k) * specular_reflectance,  cos_i = wi.z

``eval`` and ``pdf`` are 0, ``sample`` returns ``pdf`` 0 (drpt's convention
for Dirac lobes; Mitsuba reports 1), ``delta`` True, ``eta`` 1. One-sided as
the plugin (``FrontSide``): ``wi.z <= 0`` is an invalid sample with weight 0
(inside ``twosided`` the material layer flips the frame first).

Parameters (Mitsuba's names): ``material`` (a name of
:data:`drpt.materials.conductors.MATERIALS`, or ``"none"``: ``eta = 0, k = 1``, F = 1),
``eta``, ``k`` (override the material's; see :func:`drpt.materials.conductors.resolve`),
``specular_reflectance`` (rgb or texture, default 1). :func:`derive`
resolves ``eta``/``k`` host-side into the fields ``cond_eta``, ``cond_k``.

``F_c`` (:func:`fresnel_conductor`) is Mitsuba's ``fresnel_conductor``
(after Moeller, "Optics"), per channel, with ``c = cos_i``, ``s2 = 1 - c^2``::

    t    = eta^2 - k^2 - s2
    A    = sqrt(t^2 + 4 eta^2 k^2)          (= a^2 + b^2)
    a    = sqrt((A + t) / 2)
    R_s  = (A + c^2 - 2 c a) / (A + c^2 + 2 c a)
    R_p  = R_s (A c^2 + s2^2 - 2 c a s2) / (A c^2 + s2^2 + 2 c a s2)
    F_c  = (R_s + R_p) / 2

Where a denominator is 0 (Mitsuba returns NaN there) drpt takes the limit:
``R_s = 0`` (only ``eta = 1, k = 0`` at ``c = 0``: an invisible interface)
and ``R_p = R_s`` (at ``c = 1`` with ``A = 0``, e.g. ``eta = k = 0``: at
normal incidence s and p coincide).
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array2f, Array3f, Bool, Float

from ...materials import conductors
from . import BSDFSample

#: Per-material values uploaded for this kind (``cond_*`` come from :func:`derive`).
FIELDS = {"specular_reflectance": "rgb", "cond_eta": "rgb", "cond_k": "rgb"}
DELTA = True


def derive(params: dict) -> dict:
    """Host side: the resolved complex IOR (``ValueError`` for an unknown material)."""
    eta, k = conductors.resolve(params)
    return {"cond_eta": eta, "cond_k": k}


def fresnel_conductor(cos_i, eta, k):
    """Unpolarized Fresnel reflectance of a conductor (see the module docs);
    ``cos_i`` in [0, 1] (Float), ``eta``, ``k`` Array3f or Float."""
    c2 = dr.square(cos_i)
    s2 = 1.0 - c2
    s4 = dr.square(s2)
    t = dr.square(eta) - dr.square(k) - s2
    A = dr.safe_sqrt(dr.square(t) + 4.0 * dr.square(k) * dr.square(eta))
    a = dr.safe_sqrt(0.5 * (A + t))
    t1 = A + c2
    t2 = 2.0 * cos_i * a
    d1 = t1 + t2
    r_s = dr.select(d1 > 0.0, (t1 - t2) / dr.select(d1 > 0.0, d1, 1.0), 0.0)
    t3 = A * c2 + s4
    t4 = t2 * s2
    d2 = t3 + t4
    r_p = r_s * dr.select(d2 > 0.0, (t3 - t4) / dr.select(d2 > 0.0, d2, 1.0), 1.0)
    return dr.maximum(0.5 * (r_s + r_p), 0.0)


def unit_fresnel(specs) -> bool:
    """Whether every spec (of a ``conductor`` or ``roughconductor`` kind) has ``eta = 0``,
    ``k = 1`` in every channel (``material="none"``, Mitsuba's default): there
    :func:`fresnel_conductor` is exactly 1 at every angle, so a lobe may skip it (a
    trace-time choice; the same floats). With ``eta = 0``: ``t = -(1 + s2) < 0``,
    ``A = sqrt(fl(t^2)) = |t|`` exactly (the correctly rounded root of a correctly rounded
    square), so ``a = 0``, ``t2 = t4 = 0`` and ``R_s = t1 / t1 = 1``, ``R_p = R_s t3 / t3 = 1``
    (``t1, t3 > 0``)."""
    for s in specs:
        eta, k = conductors.resolve(s.params)
        if any(x != 0.0 for x in eta) or any(x != 1.0 for x in k):
            return False
    return bool(specs)


class ConductorParams:
    """Per-lane ``r`` (specular_reflectance), ``eta``, ``k`` (Array3f each)."""

    DRJIT_STRUCT = {"r": Array3f, "eta": Array3f, "k": Array3f}

    def __init__(self, r=None, eta=None, k=None, unit: bool = False):
        self.r = r if r is not None else Array3f(1.0)
        self.eta = eta if eta is not None else Array3f(0.0)
        self.k = k if k is not None else Array3f(1.0)
        #: every conductor of the kind has F = 1 (:func:`unit_fresnel`, decided at trace
        #: time; a copy Dr.Jit makes of the struct has False: F computed, the same value)
        self.unit = unit


def params(table, si, active) -> ConductorParams:
    """The lanes' parameters, gathered from the material table."""
    return ConductorParams(table.value("specular_reflectance", si, active),
                           table.value("cond_eta", si, active), table.value("cond_k", si, active),
                           unit_fresnel(table.specs_of("conductor")))


def reflectance(p, cos_i) -> Array3f:
    """``F_c(cos_i) * specular_reflectance`` of parameters ``p`` (with ``r``, ``eta``, ``k``,
    ``unit``): ``r`` itself where every conductor has F = 1 (``p.unit``)."""
    if getattr(p, "unit", False):
        return Array3f(p.r)
    return fresnel_conductor(cos_i, p.eta, p.k) * p.r


def eval(p: ConductorParams, wi: Array3f, wo: Array3f) -> Array3f:
    return dr.zeros(Array3f, dr.width(wi))


def pdf(p: ConductorParams, wi: Array3f, wo: Array3f) -> Float:
    return dr.zeros(Float, dr.width(wi))


def sample(p: ConductorParams, wi: Array3f, u1: Float, u2: Array2f) -> BSDFSample:
    n = dr.width(wi)
    valid = Bool(wi.z > 0.0)
    cos_i = dr.clip(wi.z, 0.0, 1.0)
    f = reflectance(p, cos_i)
    return BSDFSample(Array3f(-wi.x, -wi.y, wi.z), dr.select(valid, f, 0.0), dr.zeros(Float, n), valid,
                      dr.full(Bool, True, n), dr.full(Float, 1.0, n))
