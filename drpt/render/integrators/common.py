"""Pieces both integrators share: MIS weights and direct-light estimators.

:class:`DirectLight` estimates light arriving at a surface point straight
from the emitters, each estimator with its own shadow ray:

* ``area``: one point on an emissive triangle (chosen by power), weighted
  by the power heuristic against BSDF sampling when ``mis`` is set;
* ``delta``: every point and directional light;
* ``env``: one direction from the environment map (by luminance), MIS
  weighted against BSDF sampling when ``mis`` is set;

Each returns the contribution ``f * |cos| * L / pdf`` (times the MIS weight)
for lanes where it applies and zero elsewhere; none can return NaN.
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array2f, Array3f, Bool, Float

SHADOW_SHRINK = 1.0 - 2.0**-12  # stop shadow rays just short of the light


def power_heuristic(a: Float, b: Float) -> Float:
    a2, b2 = a * a, b * b
    return dr.select(a2 > 0.0, a2 / (a2 + b2), 0.0)


class DirectLight:
    def __init__(self, accel, materials, area_lights, delta_lights, offset, env=None):
        self.accel, self.mats, self.offset = accel, materials, offset
        self.area_lights = area_lights if area_lights.count > 0 else None
        self.delta_lights = delta_lights if (delta_lights and delta_lights.count) else None
        self.env = env if (env is not None and not env.is_black) else None

    def area(self, si, u_sel: Float, u2: Array2f, active: Bool, mis: bool) -> Array3f:
        ls = self.area_lights.sample(u_sel, u2, active)
        to_light = ls.p - si.p
        dist2 = dr.squared_norm(to_light)
        wo = to_light * dr.rsqrt(dist2)
        front = dr.dot(ls.n, wo) < 0.0  # the light emits toward the shading point
        cos_light = dr.abs(dr.dot(ls.ng, wo))
        f, pdf_b = self.mats.eval_pdf(si, wo)
        ok = active & front & (cos_light > 0.0) & (ls.pdf_area > 0.0) & (dr.max(f) > 0.0)
        pdf_light = ls.pdf_area * dist2 / cos_light
        so = self.offset.origin(si.p, si.ng, wo)
        ok &= ~self.accel.occluded(so, wo, dr.norm(ls.p - so) * SHADOW_SHRINK, ok)
        w = power_heuristic(pdf_light, pdf_b) if mis else Float(1.0)
        return dr.select(ok, f * ls.le * (w / pdf_light), 0.0)

    def delta(self, si, active: Bool) -> Array3f:
        total = Array3f(0.0)
        for dl in self.delta_lights.samples(si.p):
            f, _ = self.mats.eval_pdf(si, dl.wo)
            ok = active & (dr.max(f) > 0.0) & (dr.max(dl.irradiance) > 0.0)
            so = self.offset.origin(si.p, si.ng, dl.wo)
            ok &= ~self.accel.occluded(so, dl.wo, dl.dist * SHADOW_SHRINK, ok)
            total += dr.select(ok, f * dl.irradiance, 0.0)
        return total

    def env_light(self, si, u2: Array2f, active: Bool, mis: bool) -> Array3f:
        wo, radiance, pdf_l = self.env.sample(u2, active)
        f, pdf_b = self.mats.eval_pdf(si, wo)
        ok = active & (pdf_l > 0.0) & (dr.max(f) > 0.0)
        so = self.offset.origin(si.p, si.ng, wo)
        ok &= ~self.accel.occluded(so, wo, Float(dr.inf), ok)
        w = power_heuristic(pdf_l, pdf_b) if mis else Float(1.0)
        return dr.select(ok, f * radiance * (w / dr.maximum(pdf_l, 1e-30)), 0.0)
