"""Lambertian reflection ``f = kd / pi``, sampled by the cosine density.

Directions are local (shading frame, +z = normal); ``wi`` points to the
viewer, ``wo`` to the next vertex. Values include the cosine factor
``cos(wo)``. Both directions must be above the surface, else the lobe is 0
(two-sidedness is the material layer's job).
"""

from __future__ import annotations

import drjit as dr
from drjit.llvm import Array2f, Array3f, Bool, Float

from ..warp import INV_PI, cosine_hemisphere_pdf, square_to_cosine_hemisphere


def eval(kd: Array3f, wi: Array3f, wo: Array3f) -> Array3f:
    ok = (wi.z > 0.0) & (wo.z > 0.0)
    return dr.select(ok, kd * (INV_PI * wo.z), 0.0)


def pdf(wi: Array3f, wo: Array3f) -> Float:
    ok = (wi.z > 0.0) & (wo.z > 0.0)
    return dr.select(ok, cosine_hemisphere_pdf(wo.z), 0.0)


def sample(kd: Array3f, wi: Array3f, u: Array2f) -> tuple[Array3f, Array3f, Float, Bool]:
    """Returns (wo, weight = f*cos/pdf, pdf, valid)."""
    wo = square_to_cosine_hemisphere(u)
    p = cosine_hemisphere_pdf(wo.z)
    valid = (wi.z > 0.0) & (p > 0.0)
    return wo, dr.select(valid, kd, 0.0), dr.select(valid, p, 0.0), valid
