"""Thin dielectric sheet (a window pane, a soap film): Mitsuba 3's
``thindielectric`` plugin, sample for sample.

The sheet is an infinitely thin slab of a dielectric with relative IOR ``eta
= int_ior / ext_ior`` (:func:`derive`; the same parameters, names, defaults
and IOR names as :mod:`drpt.render.bsdf.dielectric`). Light bounces between
the slab's two parallel faces; summing the geometric series of internal
reflections (no absorption) with the single-interface Fresnel reflectance
``R = F(|cos_i|, eta)`` (:func:`drpt.render.bsdf.dielectric.fresnel_dielectric`)
gives the sheet's reflectance

    R' = R + T^2 R / (1 - R^2) = 2 R / (1 + R),      T = 1 - R,

and its transmittance ``1 - R'``. The two faces refract in opposite senses,
so a transmitted ray leaves *parallel to the incident one*: ``wo = -wi``
(Mitsuba's ``Null`` component, no bending, ``BSDFSample.eta`` 1, no
``eta^2`` radiance scaling since the ray ends in the medium it started in).

Sampling: ``u1 <= R'`` reflects (``wo = (-wi.x, -wi.y, wi.z)``, weight
``specular_reflectance``), else ``wo = -wi`` with weight
``specular_transmittance``; both are Dirac terms, so ``pdf`` is 0, ``delta``
True, ``eval`` and ``pdf`` are 0. The sheet is symmetric: ``|cos_i|`` is
used, so both sides behave alike (the material layer passes the unflipped
frame; nothing here depends on the side). ``eta == 1`` gives ``R = 0`` (all
light passes); ``cos_i == 0`` with ``eta != 1`` gives ``R = R' = 1``.
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array2f, Array3f, Bool, Float

from . import BSDFSample
from .dielectric import DielectricParams, derive, fresnel_dielectric, tint

__all__ = ["FIELDS", "DELTA", "derive", "params", "eval", "pdf", "sample", "reflectance"]

#: Same per-material values as the dielectric: ``rel_ior`` (from :func:`derive`) and the tints.
FIELDS = {"rel_ior": "float", "specular_reflectance": "rgb", "specular_transmittance": "rgb"}
DELTA = True

ThinDielectricParams = DielectricParams


def params(table, si, active) -> DielectricParams:
    """The parameters of the lanes' materials, gathered from the material table."""
    return DielectricParams(table.value("rel_ior", si, active),
                            tint(table, "thindielectric", "specular_reflectance", si, active),
                            tint(table, "thindielectric", "specular_transmittance", si, active))


def reflectance(cos_i: Float, eta: Float) -> Float:
    """The sheet's reflectance ``2 R / (1 + R)``, ``R = F(|cos_i|, eta)``."""
    r = fresnel_dielectric(dr.abs(Float(cos_i)), eta)[0]
    return r * 2.0 / (1.0 + r)


def eval(p: DielectricParams, wi: Array3f, wo: Array3f) -> Array3f:
    return Array3f(0.0)


def pdf(p: DielectricParams, wi: Array3f, wo: Array3f) -> Float:
    return dr.zeros(Float, dr.width(wi))


def sample(p: DielectricParams, wi: Array3f, u1: Float, u2: Array2f) -> BSDFSample:
    r = reflectance(wi.z, p.eta)
    refl = u1 <= r
    wo = dr.select(refl, Array3f(-wi.x, -wi.y, wi.z), -wi)
    w = dr.select(refl, p.r, p.t)
    n = dr.width(wi)
    return BSDFSample(wo, Array3f(w), dr.zeros(Float, n), dr.full(Bool, True, n),
                      dr.full(Bool, True, n), dr.full(Float, 1.0, n))
