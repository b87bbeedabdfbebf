"""Emissive triangles as area lights, for next-event estimation.

One triangle is chosen with probability proportional to its power
(``area * luminance(emission)``), then a point uniformly on it, so the area
density of a point ``y`` on emissive triangle ``k`` is
``pdf_A(y) = P(k) / area_k = luminance_k / sum_j(area_j * luminance_j)``:
scenes with many small emitters are not noisier than one large emitter of the
same power. The solid-angle density seen from a shading point at distance
``r`` is ``pdf_A * r^2 / |cos theta_light|``.

A textured emitter (Mitsuba's ``area`` with a bitmap ``radiance``) is chosen by
its texture's mean luminance and gives the texture's radiance at the sampled
point's uv (Mitsuba samples such an emitter by the texture instead: the
same expectation, other noise).

Emissive spheres and planes are not sampled here; they are found by BSDF
sampling only (their MIS weight is then 1, so the estimate stays unbiased).
"""

from __future__ import annotations

import drjit as dr
import numpy as np
from drjit.auto import Array2f, Array3f, Bool, Float, UInt32

from ...scene.model import Scene
from ..spawn import triangle_point
from ..surface import SurfaceData
from ..warp import square_to_uniform_triangle

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


class LightSample:
    def __init__(self, p, n, ng, le, pdf_area, valid, p_error):
        self.p: Array3f = p  # point on the light
        self.n: Array3f = n  # its front (emitting) unit normal: the shading normal
        self.ng: Array3f = ng  # its unit geometric normal (for the area Jacobian)
        self.p_error: Float = p_error  # bound on p's distance from the triangle along ng
        self.le: Array3f = le  # radiance emitted toward the front
        self.pdf_area: Float = pdf_area
        self.valid: Bool = valid


class AreaLights:
    def __init__(self, scene: Scene, surfaces: SurfaceData, materials=None):
        tris = scene.triangles
        emission = np.array([m.emission for m in scene.materials], float).reshape(-1, 3)
        self.surfaces = surfaces
        # textured emitters (Mitsuba's area radiance bitmap): the radiance at the sampled
        # point's uv (their power, for the choice of a triangle, is the texture's mean)
        self.materials = materials if getattr(materials, "_emit_tex", None) is not None else None
        self.count = 0
        if not len(tris) or not len(emission):
            return
        p = tris.positions
        area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
        lum = emission[tris.material] @ LUMINANCE
        power = area * lum
        ids = np.nonzero((power > 0) & np.isfinite(power))[0]
        if ids.size == 0:
            return
        total = power[ids].sum()
        cdf = np.cumsum(power[ids]) / total
        cdf[-1] = 1.0
        pdf_area = np.zeros(len(tris), np.float32)
        pdf_area[ids] = lum[ids] / total
        self.count = int(ids.size)
        self.total_power = float(total)
        self.ids = UInt32(ids.astype(np.uint32))
        self.cdf = Float(cdf.astype(np.float32))
        self.pdf_area_table = Float(pdf_area)
        self.le = Array3f(*(Float(emission[tris.material[ids], c].astype(np.float32)) for c in range(3)))

    def sample(self, u_select: Float, u: Array2f, active: Bool) -> LightSample:
        """A point on an emissive triangle, with its area density."""
        cdf = self.cdf
        n = self.count
        k = dr.binary_search(0, n - 1, lambda i: dr.gather(Float, cdf, i) <= u_select)
        k = dr.minimum(k, n - 1)
        face = dr.gather(UInt32, self.ids, k, active)
        s = self.surfaces
        p0 = dr.gather(Array3f, s.p0, face, active)
        e1 = dr.gather(Array3f, s.e1, face, active)
        e2 = dr.gather(Array3f, s.e2, face, active)
        b = square_to_uniform_triangle(u)
        p, ng, err = triangle_point(p0, e1, e2, b.x, b.y)
        n_front = ng
        if s.has_normals:
            sn = (dr.gather(Array3f, s.n0, face, active) * (1.0 - b.x - b.y)
                  + dr.gather(Array3f, s.n1, face, active) * b.x
                  + dr.gather(Array3f, s.n2, face, active) * b.y)
            len2 = dr.squared_norm(sn)
            n_front = dr.select(len2 > 1e-20, sn * dr.rsqrt(len2), ng)
        le = dr.gather(Array3f, self.le, k, active)
        if self.materials is not None:
            uv = Array2f(0.0, 0.0)
            if s.has_uv:
                uv = (dr.gather(Array2f, s.uv0, face, active) * (1.0 - b.x - b.y)
                      + dr.gather(Array2f, s.uv1, face, active) * b.x
                      + dr.gather(Array2f, s.uv2, face, active) * b.y)
            material = dr.gather(UInt32, s.material, face, active)
            le = self.materials.textured_emission(material, uv, le, active)
        pdf = dr.gather(Float, self.pdf_area_table, face, active)
        return LightSample(p, n_front, ng, le, pdf, active, err)

    def pdf_area(self, prim: UInt32, active: Bool) -> Float:
        """Area density with which :meth:`sample` picks a point on ``prim``."""
        is_tri = active & (prim < self.surfaces.n_tri)
        return dr.gather(Float, self.pdf_area_table, prim, is_tri)
