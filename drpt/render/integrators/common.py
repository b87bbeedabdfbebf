"""Pieces the integrators share: MIS weights and the direct-light estimator.

:class:`DirectLight` estimates light arriving at a surface point straight from the
emitters with one sample per vertex: one emitter chosen by the scene's light selection
and a direction toward it (:meth:`drpt.render.scene.DeviceScene.sample_emitter`: an
area emitter, a delta light or the sky), the BSDF toward it, weighted by the power
heuristic against BSDF sampling when ``mis`` is set (never for delta lights, which BSDF
sampling cannot hit), and one shadow ray. It returns ``f * |cos| * L / pdf`` (times the
MIS weight) where the sample carries light and zero elsewhere; never NaN.
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import Array2f, Array3f, Bool, Float, UInt32

from ..lights import EmitterSample

SHADOW_SHRINK = 1.0 - 2.0**-12  # stop shadow rays just short of their end point


def power_heuristic(a: Float, b: Float) -> Float:
    a2, b2 = a * a, b * b
    return dr.select(a2 > 0.0, a2 / (a2 + b2), 0.0)


class ShadowQuery:
    """A direct-light estimate waiting for its shadow ray: the contribution
    ``value`` (already weighted, before visibility), counted where ``ok`` and
    the segment from ``o`` along unit ``d`` is clear up to ``tmax``.
    :meth:`resolve` traces it at once (the megakernel), as a coherent query on the lanes
    ``coherent`` (a traversal hint: the same answer); the wavefront integrator collects
    the queries of a bounce and traces them as one batch. ``skip``: per lane, the box of the
    convex shape the ray leaves (:meth:`ShapeBoxes.leaving <drpt.accel.boxes.ShapeBoxes.leaving>`),
    which the query then culls by (:meth:`DeviceScene.occluded
    <drpt.render.scene.DeviceScene.occluded>`); None: every lane queries."""

    def __init__(self, value: Array3f, o: Array3f, d: Array3f, tmax: Float, ok: Bool,
                 coherent: Bool | bool = False, skip: UInt32 | None = None):
        self.value, self.o, self.d, self.tmax, self.ok = value, o, d, tmax, ok
        self.coherent, self.skip = coherent, skip

    def resolve(self, scene) -> Array3f:
        ok = self.ok & ~self._occluded(scene)
        return dr.select(ok, self.value, 0.0)

    def _occluded(self, scene) -> Bool:
        if self.skip is None:
            return scene.occluded(self.o, self.d, self.tmax, self.ok, self.coherent)
        return scene.occluded(self.o, self.d, self.tmax, self.ok, self.coherent, skip=self.skip)

    def resolve_blocked(self, scene) -> tuple[Array3f, Bool]:
        """``(estimate, blocked)``: :meth:`resolve`'s estimate and the lanes of ``ok`` whose
        segment is occluded (where a caller follows the ray on)."""
        blocked = self.ok & self._occluded(scene)
        return dr.select(self.ok & ~blocked, self.value, 0.0), blocked


def shadow_segment(o: Array3f, es) -> tuple[Array3f, Float]:
    """The shadow ray from ``o`` toward the emitter sample ``es``
    (:class:`~drpt.render.lights.EmitterSample`): its unit direction and length, up to
    ``es.p``, or along ``es.wo`` with length ``inf`` where the emitter is at infinity."""
    to = es.p - o  # to the light point, both ends off their surfaces
    dist = dr.norm(to)
    d = to / dr.maximum(dist, 1e-30)
    if es.dist is not None:
        far = dr.isinf(es.dist)
        d = dr.select(far, es.wo, d)
        dist = dr.select(far, dr.inf, dist)
    return d, dist


class DirectLight:
    """The direct-light estimator of a :class:`~drpt.render.scene.DeviceScene`:
    :meth:`emitter_query` (the emitter sample, the BSDF value and the shadow ray, as a
    :class:`ShadowQuery`), then its resolution (:meth:`emitter`)."""

    def __init__(self, scene):
        self.scene = scene

    def emitter(self, si, u_sel: Float, u2: Array2f, active: Bool, mis: bool,
                coherent: Bool | bool = False) -> Array3f:
        return self.emitter_query(si, u_sel, u2, active, mis, coherent).resolve(self.scene)

    def emitter_query(self, si, u_sel: Float, u2: Array2f, active: Bool, mis: bool,
                      coherent: Bool | bool = False) -> ShadowQuery:
        """The estimate at ``si`` waiting for its shadow ray (:class:`ShadowQuery`), whose
        query is coherent on the lanes ``coherent`` (e.g. the hits of camera rays)."""
        es = self.scene.sample_emitter(si, u_sel, u2, active)
        f, pdf_b = self.scene.eval_bsdf(si, es.wo)
        return self._query(si, es, f, pdf_b, mis, coherent)

    def emitter_query_sample(self, si, u_sel: Float, u2: Array2f, u_lobe: Float, u_bsdf: Array2f,
                             active: Bool, mis: bool, coherent: Bool | bool = False):
        """:meth:`emitter_query` and the BSDF sample from ``(u_lobe, u_bsdf)`` at ``si``,
        the BSDF evaluated and sampled in one material dispatch
        (:meth:`~drpt.render.scene.DeviceScene.eval_sample_bsdf`): ``(query, wo, bs)``,
        the same values as the two separate calls."""
        return self.sample_and_query(si, u_sel, u2, u_lobe, u_bsdf, active, mis, coherent)[3:]

    def sample_and_query(self, si, u_sel: Float, u2: Array2f, u_lobe: Float, u_bsdf: Array2f,
                         active: Bool, mis: bool, coherent: Bool | bool = False):
        """:meth:`emitter_query_sample` with the parts it is made of: ``(es, f, pdf_b,
        query, wo, bs)``, the emitter sample, the BSDF's ``f * |cos|`` and density toward
        it, then the query and the BSDF sample."""
        es = self.scene.sample_emitter(si, u_sel, u2, active)
        f, pdf_b, wo, bs = self.scene.eval_sample_bsdf(si, es.wo, u_lobe, u_bsdf)
        return es, f, pdf_b, self._query(si, es, f, pdf_b, mis, coherent), wo, bs

    def delta_each(self, si, active: Bool, coherent: Bool | bool = False) -> Array3f:
        """The direct light at ``si`` from every delta light of the scene's
        :attr:`~drpt.render.scene.DeviceScene.delta_each`, each by a shadow ray of its own
        (no selection, no random number: a delta light has one direction), summed; zero
        where the scene has none (no code traced)."""
        lights = getattr(self.scene, "delta_each", None)
        total = Array3f(0.0)
        if lights is None:
            return total
        finite = lights.count - len(lights.directionals)  # (samples(): the directional lights last)
        for i, ds in enumerate(lights.samples(si.p)):
            p = si.p + ds.wo * ds.dist if i < finite else Array3f(si.p)
            es = EmitterSample(ds.wo, p, ds.irradiance, Float(1.0), active & (dr.max(ds.irradiance) > 0.0),
                               Float(ds.dist), True)
            f, pdf_b = self.scene.eval_bsdf(si, es.wo)
            total += self._query(si, es, f, pdf_b, True, coherent).resolve(self.scene)
        return total

    def _query(self, si, es, f: Array3f, pdf_b: Float, mis: bool, coherent: Bool | bool) -> ShadowQuery:
        """The :class:`ShadowQuery` of emitter sample ``es`` at ``si`` given the BSDF's
        ``f * |cos|`` and density toward it."""
        ok = es.valid & (dr.max(f) > 0.0)
        so = self.scene.spawn(si, es.wo)
        d, dist = shadow_segment(so, es)
        w = power_heuristic(es.pdf, pdf_b) if mis and es.delta is not True else Float(1.0)
        if mis and isinstance(es.delta, Bool):  # (a scene with delta lights and others)
            w = dr.select(es.delta, 1.0, w)
        return ShadowQuery(f * es.le * (w / es.pdf), so, d, dist * SHADOW_SHRINK, ok, coherent)
