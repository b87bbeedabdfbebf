"""Emissive triangles and spheres as area lights, for next-event estimation.

An emissive *primitive* (triangle or analytic sphere) is chosen from one
discrete distribution ``P(k)``, then a point on it:

* ``power``: ``P(k)`` proportional to the
  primitive's power ``area_k * luminance_k``, so scenes with many small
  emitters are not noisier than one large emitter of the same power;
* ``uniform`` (Mitsuba's): every *emitter* equally likely, then a primitive
  of it by area: ``P(k) = area_k / (N * area_e(k))`` with ``N`` emitters;
* ``mixed`` (the default): the mean of the two probabilities;
* ``bvh``: as ``mixed`` here (light tracing's choice); next-event estimation then
  chooses among this family's slots by a light BVH at the shading point
  (:mod:`drpt.render.lights.light_bvh`, :meth:`AreaLights.bvh`).
  An emitter is a shape: a Mitsuba XML shape, the faces of one material in
  drpt's own format (:meth:`drpt.scene.model.Triangles.emitter_ids`), each
  sphere.

On a triangle the point is uniform, so its area density is
``pdf_A(y) = P(k) / area_k`` and the solid-angle density seen from a shading
point at distance ``r`` is ``pdf_A * r^2 / |cos theta_light|``. On a sphere,
seen from a point outside it (:meth:`AreaLights.sample` with ``ref``), the
direction is uniform in the cone of the visible cap (Mitsuba's
``sphere.sample_direction``): solid-angle density ``P(k) / (2 pi (1 - cos
theta_max))``, ``sin theta_max = radius / distance to the center``; from
inside, and without ``ref`` (light tracing), the point is uniform on the
sphere, ``pdf_A = P(k) / (4 pi radius^2)``. :meth:`AreaLights.pdf_sphere`
is the same density for a point a ray hit (MIS). A scene without emissive
spheres traces no sphere code.

Next-event estimation (:meth:`AreaLights.sample_direction`) can instead sample a triangle
by the solid angle it subtends (``--triangle-sampling``, :func:`triangle_sampling_rule`):
a direction uniform in its spherical triangle seen from the shading point (Arvo's warp,
:func:`drpt.render.warp.spherical_triangle_sample`), the point where it meets the
triangle, solid-angle density ``P(k) / omega``. That density has no ``r^2 / cos``, which
is unbounded at points near the light (in a medium: arbitrarily near). It is used where the
solid angle ``omega`` lies in :data:`~drpt.render.warp.SPHERICAL_MIN` ..
:data:`~drpt.render.warp.SPHERICAL_MAX` (:attr:`SphericalTriangle.sampled
<drpt.render.warp.SphericalTriangle.sampled>`), area sampling elsewhere; the density of a
BSDF-sampled ray that hits the triangle (:meth:`AreaLights.pdf_direction`, for MIS)
applies the same rule from the ray's origin, so that the two techniques' densities agree
(up to the float rounding of that origin, at the rule's bounds). Light tracing and bdpt
(:meth:`AreaLights.sample`, :meth:`DeviceScene.pdf_area_emitter
<drpt.render.scene.DeviceScene.pdf_area_emitter>`) weigh their paths by area densities
and stay on area sampling.

A textured emitter (Mitsuba's ``area`` with a bitmap ``radiance``) is weighed
by its texture's mean luminance and gives the texture's radiance at the
sampled point's uv (Mitsuba samples such an emitter by the texture instead:
the same expectation, other noise).

Emissive planes are not sampled here; they are found by BSDF sampling only
(their MIS weight is then 1, so the estimate stays unbiased).

As an :class:`~drpt.render.lights.Emitter` (next-event estimation through
:class:`~drpt.render.lights.selection.LightSelection`) a slot is one emissive
primitive with positive selection weight, in the order of :attr:`AreaLights.ids`; its
power is ``pi * area * luminance`` (one-sided Lambertian emission), times its share that
reaches the lit geometry (:mod:`drpt.render.lights.reach`). :meth:`AreaLights.bind`
gives the family the scene-wide selection's slot probabilities, and
:meth:`~AreaLights.sample_direction` / :meth:`~AreaLights.pdf_direction` use them where
:meth:`~AreaLights.sample` / :meth:`~AreaLights.pdf_area` use the family's own ``P(k)``
(light tracing chooses among area emitters alone).
"""

from __future__ import annotations

import math

import drjit as dr
import numpy as np
from drjit.auto import Array2f, Array3f, Bool, Float, UInt32

from ...options import TRIANGLE_SAMPLING
from ...scene.model import Scene
from ..spawn import origin as spawn_origin
from ..spawn import sphere_error, triangle_point
from ..surface import SurfaceData
from ..tables import Table, gather, search
from ..warp import (
    Frame,
    SphericalTriangle,
    ray_triangle_barycentrics,
    spherical_triangle_sample,
    square_to_uniform_sphere,
    square_to_uniform_triangle,
)
from . import EmitterSample
from .light_bvh import area_light_bvh
from .reach import receivers

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
LIGHT_SAMPLERS = ("mixed", "power", "uniform", "bvh", "pilot")  # drpt.options.LIGHT_SAMPLERS


def selection_weights(area: np.ndarray, lum: np.ndarray, emitter: np.ndarray,
                      sampler: str) -> np.ndarray:
    """Each primitive's weight in the light selection, ``P(k)`` up to a factor (zero
    for those that emit nothing): its power ``area * lum``, or ``uniform``: each
    emitter (``emitter`` ids) alike, then its primitives by area, or ``mixed``: half
    of each (both normalised; also ``bvh``'s)."""
    power = area * lum
    ok = (power > 0) & np.isfinite(power)
    w = np.zeros(len(area))
    if sampler in ("mixed", "bvh", "pilot") and ok.any():
        p, u = (selection_weights(area, lum, emitter, s) for s in ("power", "uniform"))
        return 0.5 * p / p.sum() + 0.5 * u / u.sum()
    if sampler == "power" or not ok.any():
        w[ok] = power[ok]
        return w
    ids, inverse = np.unique(emitter[ok], return_inverse=True)
    emitter_area = np.bincount(inverse, weights=area[ok], minlength=len(ids))
    w[ok] = area[ok] / emitter_area[inverse] / len(ids)
    return w


def _reach(scene: Scene, ids: np.ndarray, n_tri: int, rec) -> np.ndarray:
    """The share of the power of each primitive of ``ids`` (triangles, then spheres) that
    reaches ``rec``, the scene's lit geometry (:func:`~drpt.render.lights.reach.receivers`;
    1 where there is none)."""
    out = np.ones(len(ids))
    if rec is None:
        return out
    tri = ids < n_tri
    if tri.any():
        p = scene.triangles.positions[ids[tri]]
        normals = scene.triangles.normals  # the side it emits toward: its shading normal's
        n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]) if normals is None else normals[ids[tri]].mean(1)
        out[tri] = rec.flat(p.mean(1), n)
    if (~tri).any():
        out[~tri] = rec.isotropic(scene.spheres.center[ids[~tri] - n_tri])
    return out


class LightSample:
    def __init__(self, p, n, ng, le, pdf_area, valid, p_error, solid_angle=None):
        self.p: Array3f = p  # point on the light
        self.n: Array3f = n  # its front (emitting) unit normal: the shading normal
        self.ng: Array3f = ng  # its unit geometric normal (for the area Jacobian)
        self.p_error: Float = p_error  # bound on p's distance from the primitive along ng
        self.le: Array3f = le  # radiance emitted toward the front
        self.pdf_area: Float = pdf_area
        self.valid: Bool = valid
        #: lanes whose ``pdf_area`` is a solid-angle density from the reference point
        #: (a sphere's cone); None: no such lane (no emissive sphere, or no reference)
        self.solid_angle: Bool | None = solid_angle


class AreaLights:
    delta = False
    infinite = False

    def __init__(self, scene: Scene, surfaces: SurfaceData, materials=None, sampler: str = "power",
                 triangle_sampling: str = "area", integrator: str = "path", lit="scene"):
        # lit: the scene's lit geometry (drpt.render.lights.reach.receivers; "scene": computed here)
        tris, sph = scene.triangles, scene.spheres
        emission = np.array([m.emission for m in scene.materials], float).reshape(-1, 3)
        self.surfaces = surfaces
        self.sampler = sampler
        # textured emitters (Mitsuba's area radiance bitmap): the radiance at the sampled
        # point's uv (their power, for the choice of a triangle, is the texture's mean)
        self.materials = materials if getattr(materials, "has_emission_texture", False) else None
        self.count = 0
        self.n_tri = len(tris)
        self.n_sph = len(sph)
        self.has_spheres = self.has_triangles = False
        #: next-event estimation samples a triangle by its spherical triangle where its
        #: solid angle allows (:attr:`drpt.render.warp.SphericalTriangle.sampled`); light
        #: tracing and :meth:`sample` keep to area sampling
        self.spherical = False
        if not (len(tris) + len(sph)) or not len(emission):
            return
        area = np.zeros(0)
        if len(tris):
            p = tris.positions
            area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
        sph_area = 4.0 * np.pi * np.asarray(sph.radius, float) ** 2
        mats = np.concatenate([tris.material, sph.material]).astype(np.int64)
        lum = emission[mats] @ LUMINANCE
        all_area = np.concatenate([area, sph_area])
        power = all_area * lum
        emitter = np.concatenate([tris.emitter_ids() if len(tris) else np.zeros(0, np.int64),
                                  np.arange(len(sph)) + (int(tris.emitter_ids().max()) + 1 if len(tris) else 0)])
        weight = selection_weights(all_area, lum, emitter, sampler)
        ids = np.nonzero((weight > 0) & np.isfinite(weight))[0]
        if ids.size == 0:
            return
        total = weight[ids].sum()
        keep = np.zeros(len(all_area), bool)
        keep[ids] = True
        prob = np.where(keep, weight / total, 0.0)
        cdf = np.cumsum(weight[ids]) / total
        cdf[-1] = 1.0
        # area density of a point: P(k) / area_k (by power: luminance_k / total power)
        pdf_area = np.where(keep, prob / np.where(keep, all_area, 1.0), 0.0)
        self.count = int(ids.size)
        self.emitters = int(np.unique(emitter[ids]).size)
        self.total_power = float(power[ids].sum())
        #: P(k) of each primitive (triangles, then spheres), for tests and tools
        self.probabilities = prob
        # (small tables: read as literals where they are few, drpt.render.tables)
        self.ids = Table(UInt32, ids)
        self.cdf = Table(Float, cdf)
        self.pdf_area_table = Table(Float, pdf_area[:self.n_tri]) if self.n_tri else None
        self.le = Table(Array3f, emission[mats[ids]])
        self.has_spheres = bool((ids >= self.n_tri).any())
        self.has_triangles = bool((ids < self.n_tri).any())
        self.spherical = self.has_triangles and triangle_sampling_rule(triangle_sampling, scene, integrator)
        #: the records of the emissive triangles where they are few (literals in the kernel,
        #: :meth:`SurfaceData.records <drpt.render.surface.SurfaceData.records>`), else None
        self.tri_records = surfaces.records(ids[ids < self.n_tri]) if self.has_triangles else None
        if self.has_spheres:
            # per sphere: its selection probability P(k) (its area density is P(k) / 4 pi r^2)
            self.sph_prob = Table(Float, prob[self.n_tri:])
        if self.n_tri == 0:
            # no triangles: the triangle branch is never traced, but keep a table to gather from
            self.pdf_area_table = Table(Float, np.zeros(1))
        # the slots of the Emitter interface: the primitives of ids, in that order
        self._area = all_area
        self._ids = ids
        self._lum = lum
        #: each slot's power that reaches the lit geometry (:mod:`drpt.render.lights.reach`)
        self._power = np.pi * power[ids] * _reach(scene, ids, self.n_tri, receivers(scene) if lit == "scene" else lit)
        _, self._unit = np.unique(emitter[ids], return_inverse=True)
        unit_area = np.bincount(self._unit, weights=all_area[ids])
        self._share = all_area[ids] / unit_area[self._unit]
        self.bind(prob[ids])

    # ------------------------------------------------------------ Emitter interface
    def power(self) -> np.ndarray:
        """Each slot's power, ``pi * area * luminance`` (W; a textured emitter's mean), times
        its share that reaches the lit geometry (:mod:`drpt.render.lights.reach`)."""
        return self._power if self.count else np.zeros(0)

    def units(self) -> tuple[np.ndarray, np.ndarray]:
        """Each slot's emitter (a shape: :meth:`drpt.scene.model.Triangles.emitter_ids`, a
        sphere) and its share of that emitter's area."""
        if not self.count:
            return np.zeros(0, np.int64), np.zeros(0)
        return self._unit, self._share

    def bind(self, prob: np.ndarray | None) -> None:
        """The slot probabilities :meth:`sample_direction` and :meth:`pdf_direction` include
        (``None``: 1 each, densities conditional on the slot), as per-primitive tables:
        ``prob / area`` per triangle, ``prob`` per sphere, and each primitive's slot
        (:meth:`slot_of`)."""
        if not self.count:
            return
        p = np.ones(self.count) if prob is None else np.asarray(prob, np.float64)
        full = np.zeros(len(self._area))
        full[self._ids] = p
        slot = np.zeros(len(self._area), np.uint32)
        slot[self._ids] = np.arange(self.count, dtype=np.uint32)
        self._slot = Table(UInt32, slot)
        tri = full[:self.n_tri] / np.where(full[:self.n_tri] > 0, self._area[:self.n_tri], 1.0)
        self.nee_pdf_area = Table(Float, tri if self.n_tri else np.zeros(1))
        if self.spherical:  # each triangle's probability: the solid-angle density's numerator
            self.nee_tri_prob = Table(Float, full[:self.n_tri])
        if self.has_spheres:
            self.nee_sph_prob = Table(Float, full[self.n_tri:])

    def bvh(self, scene: Scene):
        """A :class:`~drpt.render.lights.light_bvh.LightBVH` over this family's slots
        (item ``k`` is slot ``k``), from the primitives of ``scene`` it was built from."""
        return area_light_bvh(scene, self._ids, self.n_tri, self._area, self._lum)

    def slot_of(self, prim: UInt32, active: Bool) -> UInt32:
        """The slot of primitive ``prim`` (meaningful where :meth:`pdf_direction` is not 0)."""
        return gather(UInt32, self._slot, prim, active)

    def sample_direction(self, ref: Array3f, slot: UInt32, u: Array2f, active: Bool) -> EmitterSample:
        """A point on the primitive of ``slot`` seen from ``ref`` (a sphere's by the cone it
        subtends), with the solid-angle density times the bound slot probability."""
        face = gather(UInt32, self.ids, slot, active)
        le = gather(Array3f, self.le, slot, active)
        ls = self._point(face, u, le, active, ref if self.has_spheres or self.spherical else None,
                         self.nee_pdf_area, getattr(self, "nee_sph_prob", None),
                         getattr(self, "nee_tri_prob", None))
        return toward(ref, ls, active)

    def pdf_direction(self, si, d: Array3f, active: Bool, ref: Array3f | None = None) -> Float:
        """The density of :meth:`sample_direction` for the point ``si`` a ray of unit
        direction ``d`` hit at distance ``si.t`` (0 where it is not a slot's primitive),
        seen from ``ref`` (None: where the ray started, ``si.p - d * si.t``)."""
        return self._pdf_hit(si, d, active, self.nee_pdf_area, getattr(self, "nee_sph_prob", None),
                             getattr(self, "nee_tri_prob", None), ref)

    def _pdf_hit(self, si, d: Array3f, active: Bool, table: Float, sph_prob, tri_prob=None,
                 ref: Array3f | None = None) -> Float:
        pdf_a = self.pdf_area(si.prim, active, table)
        sees_light = active & (pdf_a > 0.0)
        dist = si.t if ref is None else dr.norm(si.p - ref)
        pdf = dr.select(sees_light, pdf_a * dr.square(dist) / dr.abs(dr.dot(si.ng, d)), 0.0)
        if ref is None:
            ref = si.p - d * si.t  # where the ray came from
        if tri_prob is not None:  # the spherical triangle seen from there
            s = self.surfaces
            face = dr.select(sees_light, si.prim, 0)
            tri = s.triangle(face, sees_light)
            st = SphericalTriangle(tri.p0, tri.e1, tri.e2, ref)
            solid = sees_light & st.sampled
            pdf = dr.select(solid, gather(Float, tri_prob, face, solid) / st.omega, pdf)
        if self.has_spheres:
            is_sph, pdf_s = self.pdf_sphere(si.prim, si.p, ref, d, dist, active & si.valid, sph_prob)
            pdf = dr.select(is_sph, pdf_s, pdf)
        return pdf

    # ------------------------------------------------------------ the family's own selection

    def _select(self, u_select: Float, active: Bool):
        k = dr.minimum(search(self.cdf, u_select), self.count - 1)
        return k, gather(UInt32, self.ids, k, active)

    def reuse(self, u: Array2f, active: Bool) -> tuple[Float, Array2f]:
        """The light selection drawn from ``u.x`` and ``u`` with ``u.x`` rescaled to the
        selected primitive's interval of the CDF, to pass to :meth:`sample` (Mitsuba's
        sample reuse): the primitive and the point on it then come from one 2-D sample,
        so a stratified 2-D sample stays stratified over the lights' surfaces (the
        low-discrepancy sampler's NEE, :mod:`drpt.render.sampler`)."""
        k, _ = self._select(u.x, active)
        hi = gather(Float, self.cdf, k, active)
        lo = dr.select(k > 0, gather(Float, self.cdf, dr.maximum(k, 1) - 1, active & (k > 0)), 0.0)
        x = (u.x - lo) / dr.maximum(hi - lo, 1e-30)
        return u.x, Array2f(dr.clip(x, 0.0, 0.99999994), u.y)

    def sample(self, u_select: Float, u: Array2f, active: Bool, ref: Array3f | None = None) -> LightSample:
        """A point on an emissive primitive, with its area density. On a sphere the
        point is uniform on it, or with ``ref`` (a shading point outside it) in the
        cone of its cap seen from ``ref``, with the solid-angle density (``solid_angle``)."""
        k, face = self._select(u_select, active)
        le = gather(Array3f, self.le, k, active)
        return self._point(face, u, le, active, ref, self.pdf_area_table, getattr(self, "sph_prob", None))

    def _point(self, face: UInt32, u: Array2f, le: Array3f, active: Bool, ref, table: Float,
               sph_prob, tri_prob=None) -> LightSample:
        """A point on primitive ``face`` with the density tables ``table`` (per triangle,
        area density), ``sph_prob`` (per sphere, its probability) and ``tri_prob`` (per
        triangle, its probability: sampled by the spherical triangle seen from ``ref``
        where :attr:`SphericalTriangle.sampled <drpt.render.warp.SphericalTriangle.sampled>`;
        None: by area)."""
        if not self.has_spheres:
            p, n_front, ng, err, pdf, le, solid = self._triangle_point(face, u, le, active, table, ref, tri_prob)
            return LightSample(p, n_front, ng, le, pdf, active, err, solid)
        is_sph = face >= self.n_tri
        solid_tri = None
        if self.has_triangles:
            tri = active & ~is_sph
            p, n_front, ng, err, pdf, le, solid_tri = self._triangle_point(dr.select(is_sph, 0, face), u, le,
                                                                           tri, table, ref, tri_prob)
        else:
            p, n_front, ng, err, pdf = (Array3f(0.0), Array3f(0.0, 0.0, 1.0), Array3f(0.0, 0.0, 1.0),
                                        Float(0.0), Float(0.0))
        sa = active & is_sph
        sp, sn, serr, spdf, solid = self._sphere_point(face - self.n_tri, u, sa, ref, sph_prob)
        p = dr.select(is_sph, sp, p)
        n_front = dr.select(is_sph, sn, n_front)
        ng = dr.select(is_sph, sn, ng)
        err = dr.select(is_sph, serr, err)
        pdf = dr.select(is_sph, spdf, pdf)
        if solid is not None:
            solid = is_sph & solid
        if solid_tri is not None:
            solid = solid_tri if solid is None else solid | solid_tri
        return LightSample(p, n_front, ng, le, pdf, active, err, solid)

    def _triangle_point(self, face: UInt32, u: Array2f, le: Array3f, active: Bool, table: Float,
                        ref: Array3f | None = None, tri_prob: Float | None = None):
        """A point on triangle ``face``: ``(p, front normal, ng, p_error, density, le,
        solid)``, ``solid`` the lanes whose density is in solid angle (None: none)."""
        s = self.surfaces
        tri = s.triangle(face, active, normals=True, uv=self.materials is not None, among=self.tri_records)
        p0, e1, e2 = tri.p0, tri.e1, tri.e2
        b = square_to_uniform_triangle(u)
        pdf = gather(Float, table, face, active)
        solid = None
        if tri_prob is not None and ref is not None:
            st = SphericalTriangle(p0, e1, e2, ref)
            solid = active & st.sampled
            w = spherical_triangle_sample(st, u)
            b = dr.select(solid, ray_triangle_barycentrics(ref, w, p0, e1, e2), b)
            pdf = dr.select(solid, gather(Float, tri_prob, face, solid) / st.omega, pdf)
        p, ng, err = triangle_point(p0, e1, e2, b.x, b.y)
        n_front = ng
        if tri.n is not None:
            sn = tri.n[0] * (1.0 - b.x - b.y) + tri.n[1] * b.x + tri.n[2] * b.y
            len2 = dr.squared_norm(sn)
            n_front = dr.select(len2 > 1e-20, sn * dr.rsqrt(len2), ng)
        if self.materials is not None:
            uv = Array2f(0.0, 0.0)
            if tri.uv is not None:
                uv = tri.uv[0] * (1.0 - b.x - b.y) + tri.uv[1] * b.x + tri.uv[2] * b.y
            material = gather(UInt32, s.material, face, active)
            le = self.materials.textured_emission(material, uv, le, active)
        return p, n_front, ng, err, pdf, le, solid

    def _sphere_point(self, j: UInt32, u: Array2f, active: Bool, ref: Array3f | None, sph_prob: Float):
        """A point on sphere ``j``: ``(p, outward normal, p_error, density, solid_angle)``."""
        s = self.surfaces
        j = dr.select(active, j, 0)
        c = gather(Array3f, s.sph_c, j, active)
        r = gather(Float, s.sph_r, j, active)
        prob = gather(Float, sph_prob, j, active)
        n = square_to_uniform_sphere(u)
        pdf = prob / (4.0 * dr.pi * r * r)
        solid = None
        if ref is not None:
            outside, omc, sin2_max, axis = cone_of(c, r, ref)
            # a direction uniform in the cone (1 - cos theta = u omc, exact), then the
            # point of the sphere it meets first, by its angle alpha at the center
            v = u.x * omc
            sin2_t = v * (2.0 - v)
            cos_t = 1.0 - v
            inv_sin_max = dr.rsqrt(dr.maximum(sin2_max, 1e-30))
            cos_a = (sin2_t * inv_sin_max
                     + cos_t * dr.safe_sqrt(1.0 - sin2_t * dr.square(inv_sin_max)))
            sin_a = dr.safe_sqrt(1.0 - cos_a * cos_a)
            sp, cp = dr.sincos(2.0 * dr.pi * u.y)
            nc = Frame(axis).to_world(Array3f(cp * sin_a, sp * sin_a, cos_a))
            n = dr.select(outside, nc, n)
            pdf = dr.select(outside, prob * cone_pdf(omc), pdf)
            solid = outside
        p = c + n * r
        return p, n, sphere_error(p, r, n), pdf, solid

    def pdf_area(self, prim: UInt32, active: Bool, table: Float | None = None) -> Float:
        """Area density with which :meth:`sample` picks a point on triangle ``prim``
        (with ``table``: that per-triangle table's)."""
        is_tri = active & (prim < self.surfaces.n_tri)
        return gather(Float, self.pdf_area_table if table is None else table, prim, is_tri)

    def pdf_sphere(self, prim: UInt32, p: Array3f, ref: Array3f, d: Array3f, dist: Float,
                   active: Bool, sph_prob: Float | None = None) -> tuple[Bool, Float]:
        """The solid-angle density with which :meth:`sample` (with ``ref``) gives the
        direction ``d`` toward point ``p`` of sphere ``prim`` at ``dist``: ``(is_sphere, pdf)``."""
        s = self.surfaces
        is_sph = active & (prim >= self.n_tri) & (prim < self.n_tri + s.n_sph)
        j = dr.select(is_sph, prim - self.n_tri, 0)
        c = gather(Array3f, s.sph_c, j, is_sph)
        r = gather(Float, s.sph_r, j, is_sph)
        prob = gather(Float, self.sph_prob if sph_prob is None else sph_prob, j, is_sph)
        outside, omc, _, _ = cone_of(c, r, ref)
        n = dr.normalize(p - c)
        area = prob / (4.0 * dr.pi * r * r) * dr.square(dist) / dr.abs(dr.dot(n, d))
        pdf = dr.select(outside, prob * cone_pdf(omc), area)
        return is_sph, dr.select(is_sph & (prob > 0.0), pdf, 0.0)


def toward(ref: Array3f, ls: LightSample, active: Bool) -> EmitterSample:
    """The direction from ``ref`` toward the light point ``ls``, with its solid-angle
    density: ``pdf_area * r^2 / |cos theta_light|``, or a sphere's cone density as it
    is. Only the front of an emitter (its shading normal's side) emits."""
    to_light = ls.p - ref
    dist2 = dr.squared_norm(to_light)
    wo = to_light * dr.rsqrt(dist2)
    front = dr.dot(ls.n, wo) < 0.0  # the light emits toward the reference point
    cos_light = dr.abs(dr.dot(ls.ng, wo))
    valid = active & front & (cos_light > 0.0) & (ls.pdf_area > 0.0)
    pdf = ls.pdf_area * dist2 / cos_light
    if ls.solid_angle is not None:
        pdf = dr.select(ls.solid_angle, ls.pdf_area, pdf)
    p_end = spawn_origin(ls.p, ls.ng, ls.p_error, -wo)
    return EmitterSample(wo, p_end, ls.le, pdf, valid)


def cone_of(c: Array3f, r: Float, ref: Array3f):
    """The cone of sphere ``(c, r)`` seen from ``ref``: ``(outside, 1 - cos theta_max,
    sin^2 theta_max, unit axis from the center toward ref)``. ``1 - cos`` is computed as
    ``sin^2 / (1 + cos)``, exact for tiny or distant spheres."""
    dc = ref - c
    dc2 = dr.squared_norm(dc)
    outside = dc2 > r * r
    sin2_max = dr.minimum(r * r / dr.maximum(dc2, 1e-30), 1.0)
    cos_max = dr.safe_sqrt(1.0 - sin2_max)
    omc = sin2_max / (1.0 + cos_max)
    return outside, omc, sin2_max, dc * dr.rsqrt(dr.maximum(dc2, 1e-30))


def cone_pdf(one_minus_cos: Float) -> Float:
    """Density of a direction uniform in a cone of ``1 - cos theta_max``."""
    return dr.select(one_minus_cos > 0.0, 1.0 / (2.0 * math.pi * dr.maximum(one_minus_cos, 1e-30)), 0.0)


def triangle_sampling_rule(mode: str, scene: Scene, integrator: str) -> bool:
    """Whether next-event estimation samples the emissive triangles by their spherical
    triangles (``--triangle-sampling``): ``area`` never, ``solid-angle`` always (where the
    solid angle allows, :attr:`~drpt.render.warp.SphericalTriangle.sampled`), ``auto`` where
    ``volpath`` renders a scene with participating media (``path`` and ``whitted`` pass
    through its media, so nothing changes there). In a medium next-event estimation starts at points in
    the medium, which come arbitrarily near a light: the area density's ``r^2 / cos``
    leaves such a point's estimate unbounded (a few bright fireflies near every light), the
    solid angle's does not. Where only surfaces receive light, the spherical triangle's
    extra work costs more time than it saves noise (docs/performance.md, "Emissive
    triangles by solid angle")."""
    if mode not in TRIANGLE_SAMPLING:
        raise ValueError(f"triangle sampling {mode!r}: not one of {', '.join(TRIANGLE_SAMPLING)}")
    if mode == "auto":
        return bool(scene.media) and integrator == "volpath"
    return mode == "solid-angle"
