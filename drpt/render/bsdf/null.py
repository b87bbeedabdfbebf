"""The pass-through of Mitsuba's ``mask``: the ray continues unchanged.

A Dirac lobe: ``sample`` returns ``wo = -wi`` with weight 1, ``pdf`` 0,
``delta`` True, ``eta`` 1 (nothing is refracted); ``eval`` and ``pdf`` are 0.
The material layer weighs it by ``1 - opacity`` (:mod:`drpt.render.material`).
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array2f, Array3f, Bool, Float

from . import BSDFSample

FIELDS: dict = {}
DELTA = True


class NullParams:
    DRJIT_STRUCT: dict = {}


def params(table, si, active) -> NullParams:
    return NullParams()


def eval(p: NullParams, wi: Array3f, wo: Array3f) -> Array3f:
    return Array3f(0.0)


def pdf(p: NullParams, wi: Array3f, wo: Array3f) -> Float:
    return dr.zeros(Float, dr.width(wi))


def sample(p: NullParams, wi: Array3f, u1: Float, u2: Array2f) -> BSDFSample:
    n = dr.width(wi)
    return BSDFSample(-wi, dr.full(Array3f, 1.0, n), dr.zeros(Float, n), dr.full(Bool, True, n),
                      dr.full(Bool, True, n), dr.full(Float, 1.0, n))
