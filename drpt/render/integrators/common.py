"""Pieces both integrators share: MIS weights and direct-light estimators.

:class:`DirectLight` estimates light arriving at a surface point straight
from the emitters, each estimator with its own shadow ray:

* ``area``: one point on an emissive triangle (chosen by power), weighted
  by the power heuristic against BSDF sampling when ``mis`` is set;
* ``delta``: every point and directional light;
* ``env``: one direction from the environment map (by luminance), MIS
  weighted against BSDF sampling when ``mis`` is set;

Each queries the scene (:class:`drpt.render.scene.DeviceScene`) for the
emitter sample, the BSDF and the shadow ray, and returns the contribution ``f * |cos| * L / pdf`` (times the MIS weight)
for lanes where it applies and zero elsewhere; none can return NaN.
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array2f, Array3f, Bool, Float

SHADOW_SHRINK = 1.0 - 2.0**-12  # stop shadow rays just short of their end point


def power_heuristic(a: Float, b: Float) -> Float:
    a2, b2 = a * a, b * b
    return dr.select(a2 > 0.0, a2 / (a2 + b2), 0.0)


class DirectLight:
    """The direct-light estimators of a :class:`~drpt.render.scene.DeviceScene`."""

    def __init__(self, scene):
        self.scene = scene

    def area(self, si, u_sel: Float, u2: Array2f, active: Bool, mis: bool) -> Array3f:
        scene = self.scene
        ls = scene.sample_area_emitter(si, u_sel, u2, active)
        f, pdf_b = scene.eval_bsdf(si, ls.wo)
        ok = ls.valid & (dr.max(f) > 0.0)
        so = scene.spawn(si, ls.wo)
        to = ls.p - so  # to the light point, both ends off their surfaces
        dist = dr.norm(to)
        ok &= ~scene.occluded(so, to / dr.maximum(dist, 1e-30), dist * SHADOW_SHRINK, ok)
        w = power_heuristic(ls.pdf, pdf_b) if mis else Float(1.0)
        return dr.select(ok, f * ls.le * (w / ls.pdf), 0.0)

    def delta(self, si, active: Bool) -> Array3f:
        scene = self.scene
        total = Array3f(0.0)
        for dl in scene.delta_emitters(si.p):
            f, _ = scene.eval_bsdf(si, dl.wo)
            ok = active & (dr.max(f) > 0.0) & (dr.max(dl.irradiance) > 0.0)
            so = scene.spawn(si, dl.wo)
            ok &= ~scene.occluded(so, dl.wo, dl.dist * SHADOW_SHRINK, ok)
            total += dr.select(ok, f * dl.irradiance, 0.0)
        return total

    def env_light(self, si, u2: Array2f, active: Bool, mis: bool) -> Array3f:
        scene = self.scene
        wo, radiance, pdf_l = scene.sample_environment(u2, active)
        f, pdf_b = scene.eval_bsdf(si, wo)
        ok = active & (pdf_l > 0.0) & (dr.max(f) > 0.0)
        so = scene.spawn(si, wo)
        ok &= ~scene.occluded(so, wo, Float(dr.inf), ok)
        w = power_heuristic(pdf_l, pdf_b) if mis else Float(1.0)
        return dr.select(ok, f * radiance * (w / dr.maximum(pdf_l, 1e-30)), 0.0)
