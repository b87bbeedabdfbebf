"""Perfect specular reflection with a colored reflectance ``r``.

A delta lobe: ``sample`` returns ``wo = (-wi.x, -wi.y, wi.z)`` with weight
``r`` (the ratio of Dirac terms: ``f * |cos| / pdf = r``), ``pdf`` 0,
``delta`` True, ``eta`` 1. ``eval`` and ``pdf`` are 0. The material layer
flips the frame to the viewer's side; ``wi.z <= 0`` gives an invalid sample
with weight 0. Equals Mitsuba's ``conductor`` with ``material="none"``
(Fresnel factor 1) and ``specular_reflectance = r``.
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array2f, Array3f, Bool, Float

from . import BSDFSample

#: Spec fields the material table uploads for this lobe (see :class:`drpt.render.bsdf.BSDF`).
FIELDS = {"ks": "rgb"}
DELTA = True


class MirrorParams:
    DRJIT_STRUCT = {"r": Array3f}

    def __init__(self, r=None):
        self.r = r if r is not None else Array3f(1.0)


def params(table, si, active) -> MirrorParams:
    """The parameters of the lanes' materials, gathered from the material table."""
    return MirrorParams(table.value("ks", si, active))


def eval(p: MirrorParams, wi: Array3f, wo: Array3f) -> Array3f:
    return Array3f(0.0)


def pdf(p: MirrorParams, wi: Array3f, wo: Array3f) -> Float:
    return dr.zeros(Float, dr.width(wi))


def sample(p: MirrorParams, wi: Array3f, u1: Float, u2: Array2f) -> BSDFSample:
    valid = Bool(wi.z > 0.0)
    n = dr.width(wi)
    wo = Array3f(-wi.x, -wi.y, wi.z)
    return BSDFSample(wo, dr.select(valid, p.r, 0.0), dr.zeros(Float, n), valid,
                      dr.full(Bool, True, n), dr.full(Float, 1.0, n))
