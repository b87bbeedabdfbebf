"""Lambertian reflection ``f = kd / pi``, sampled by the cosine density.

Follows the lobe interface of :mod:`drpt.render.bsdf`: local directions,
``wi`` toward the viewer, ``eval`` includes ``cos(wo)``. Both directions
must be above the surface, else the lobe is 0 (two-sidedness is the
material layer's job).
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array2f, Array3f, Float

from ..warp import INV_PI, cosine_hemisphere_pdf, square_to_cosine_hemisphere
from . import BSDFSample

#: Spec fields the material table uploads for this lobe (see :class:`drpt.render.bsdf.BSDF`).
FIELDS = {"kd": "rgb"}
#: The field the Whitted ambient term multiplies.
COLOR = "kd"
DELTA = False


class DiffuseParams:
    DRJIT_STRUCT = {"kd": Array3f}

    def __init__(self, kd=None):
        self.kd = kd if kd is not None else Array3f(0.5)


def params(table, si, active) -> DiffuseParams:
    """The parameters of the lanes' materials, gathered from the material table."""
    return DiffuseParams(table.value("kd", si, active))


def eval(p: DiffuseParams, wi: Array3f, wo: Array3f) -> Array3f:
    ok = (wi.z > 0.0) & (wo.z > 0.0)
    return dr.select(ok, p.kd * (INV_PI * wo.z), 0.0)


def pdf(p: DiffuseParams, wi: Array3f, wo: Array3f) -> Float:
    ok = (wi.z > 0.0) & (wo.z > 0.0)
    return dr.select(ok, cosine_hemisphere_pdf(wo.z), 0.0)


def sample(p: DiffuseParams, wi: Array3f, u1: Float, u2: Array2f) -> BSDFSample:
    wo = square_to_cosine_hemisphere(u2)
    pd = cosine_hemisphere_pdf(wo.z)
    valid = (wi.z > 0.0) & (pd > 0.0)
    return BSDFSample(wo, dr.select(valid, p.kd, 0.0), dr.select(valid, pd, 0.0), valid)
