"""Pieces both integrators share: MIS weights and direct-light estimators.

:class:`DirectLight` estimates light arriving at a surface point straight
from the emitters, each estimator with its own shadow ray:

* ``area``: one point on an emissive triangle or sphere (chosen by the light
  sampler; on a sphere by the cone it subtends), weighted
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


class ShadowQuery:
    """A direct-light estimate waiting for its shadow ray: the contribution
    ``value`` (already weighted, before visibility), counted where ``ok`` and
    the segment from ``o`` along unit ``d`` is clear up to ``tmax``.
    :meth:`resolve` traces it at once (the megakernel); the wavefront
    integrator collects the queries of a bounce and traces them as one batch."""

    def __init__(self, value: Array3f, o: Array3f, d: Array3f, tmax: Float, ok: Bool):
        self.value, self.o, self.d, self.tmax, self.ok = value, o, d, tmax, ok

    def resolve(self, scene) -> Array3f:
        ok = self.ok & ~scene.occluded(self.o, self.d, self.tmax, self.ok)
        return dr.select(ok, self.value, 0.0)


class DirectLight:
    """The direct-light estimators of a :class:`~drpt.render.scene.DeviceScene`.

    Each estimator ``X`` is ``X_queries`` (the emitter samples, BSDF values and
    shadow rays, as :class:`ShadowQuery` objects) then their resolution."""

    def __init__(self, scene):
        self.scene = scene

    def area(self, si, u_sel: Float, u2: Array2f, active: Bool, mis: bool) -> Array3f:
        return self.area_query(si, u_sel, u2, active, mis).resolve(self.scene)

    def area_query(self, si, u_sel: Float, u2: Array2f, active: Bool, mis: bool) -> ShadowQuery:
        scene = self.scene
        ls = scene.sample_area_emitter(si, u_sel, u2, active)
        f, pdf_b = scene.eval_bsdf(si, ls.wo)
        ok = ls.valid & (dr.max(f) > 0.0)
        so = scene.spawn(si, ls.wo)
        to = ls.p - so  # to the light point, both ends off their surfaces
        dist = dr.norm(to)
        w = power_heuristic(ls.pdf, pdf_b) if mis else Float(1.0)
        return ShadowQuery(f * ls.le * (w / ls.pdf), so, to / dr.maximum(dist, 1e-30),
                           dist * SHADOW_SHRINK, ok)

    def delta(self, si, active: Bool) -> Array3f:
        total = Array3f(0.0)
        for q in self.delta_queries(si, active):
            total += q.resolve(self.scene)
        return total

    def delta_queries(self, si, active: Bool) -> list[ShadowQuery]:
        scene = self.scene
        out = []
        for dl in scene.delta_emitters(si.p):
            f, _ = scene.eval_bsdf(si, dl.wo)
            ok = active & (dr.max(f) > 0.0) & (dr.max(dl.irradiance) > 0.0)
            so = scene.spawn(si, dl.wo)
            out.append(ShadowQuery(f * dl.irradiance, so, dl.wo, dl.dist * SHADOW_SHRINK, ok))
        return out

    def env_light(self, si, u2: Array2f, active: Bool, mis: bool) -> Array3f:
        return self.env_query(si, u2, active, mis).resolve(self.scene)

    def env_query(self, si, u2: Array2f, active: Bool, mis: bool) -> ShadowQuery:
        scene = self.scene
        wo, radiance, pdf_l = scene.sample_environment(u2, active)
        f, pdf_b = scene.eval_bsdf(si, wo)
        ok = active & (pdf_l > 0.0) & (dr.max(f) > 0.0)
        so = scene.spawn(si, wo)
        w = power_heuristic(pdf_l, pdf_b) if mis else Float(1.0)
        return ShadowQuery(f * radiance * (w / dr.maximum(pdf_l, 1e-30)), so, wo, Float(dr.inf), ok)
