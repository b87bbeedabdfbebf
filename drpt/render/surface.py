"""Surface interactions: what the integrator knows about a ray's hit.

:class:`SurfaceData` holds the per-primitive attributes on the device, in the
scene's original primitive order and in the accel's global id space
(triangles ``0..F-1``, spheres ``F..F+S-1``, planes ``F+S..F+S+P-1``).
:meth:`SurfaceData.interaction` turns an accel ``Hit`` into a
:class:`Interaction`. Only the primitive kinds the scene has are traced.
"""

from __future__ import annotations

import drjit as dr
import numpy as np
from drjit.auto import Array2f, Array3f, Bool, Float, UInt32

from ..scene.model import Scene
from .spawn import plane_error, plane_project, sphere_error, triangle_point


def _vec(a: np.ndarray) -> Array3f:
    a = np.ascontiguousarray(a, dtype=np.float32).reshape(-1, 3)
    return Array3f(Float(a[:, 0]), Float(a[:, 1]), Float(a[:, 2]))


class Interaction:
    """A ray's hit: position, normals, material and the direction back to the viewer.

    ``ng`` is the unit geometric normal with its *defining* orientation
    (triangle winding, sphere outward, plane as given), ``ns`` the unit
    shading normal (interpolated OBJ normals, else ``ng``). ``ns`` is not
    forced onto ``ng``'s side: it defines the front of an emitter, as in
    Mitsuba. ``wi`` points from the hit back along the incoming ray.
    ``p_error`` bounds the distance of ``p`` from the primitive's float32
    surface along ``ng`` (:mod:`drpt.render.spawn`; zero on a miss).
    """

    def __init__(self, valid, t, p, ng, ns, prim, material, wi, uv=None, p_error=None):
        self.valid: Bool = valid
        self.t: Float = t
        self.p: Array3f = p
        self.ng: Array3f = ng
        self.ns: Array3f = ns
        self.prim: UInt32 = prim
        self.material: UInt32 = material
        self.wi: Array3f = wi
        self.uv: Array2f = uv if uv is not None else Array2f(0.0, 0.0)  # OBJ convention
        self.p_error: Float = p_error if p_error is not None else Float(0.0)

    def is_triangle(self, n_triangles: int) -> Bool:
        return self.valid & (self.prim < n_triangles)


class SurfaceData:
    def __init__(self, scene: Scene, with_uv: bool = False):
        tris, sph, pl = scene.triangles, scene.spheres, scene.planes
        self.n_tri, self.n_sph, self.n_pl = len(tris), len(sph), len(pl)
        if self.n_tri:
            # Edges of the float32 vertices the accelerators test, so that
            # p0 + u e1 + v e2 is rounded from a point of that triangle.
            p = np.asarray(tris.positions, np.float32).astype(np.float64)
            self.p0 = _vec(p[:, 0])
            self.e1 = _vec(p[:, 1] - p[:, 0])
            self.e2 = _vec(p[:, 2] - p[:, 0])
            self.has_normals = tris.normals is not None
            self.has_uv = with_uv and tris.uvs is not None
            if self.has_uv:
                uv = np.asarray(tris.uvs, np.float32)
                self.uv0, self.uv1, self.uv2 = (
                    Array2f(np.ascontiguousarray(uv[:, k, 0]), np.ascontiguousarray(uv[:, k, 1]))
                    for k in range(3))
            if self.has_normals:
                self.n0, self.n1, self.n2 = (_vec(tris.normals[:, k]) for k in range(3))
        if self.n_sph:
            self.sph_c = _vec(sph.center)
            self.sph_r = Float(sph.radius.astype(np.float32))
        if self.n_pl:
            self.pl_n = _vec(pl.normal)
            self.pl_o = Float(np.asarray(pl.offset, np.float32))
        mats = np.concatenate([tris.material, sph.material, pl.material]).astype(np.uint32)
        self.material = UInt32(mats)

    # ------------------------------------------------------------------
    def interaction(self, o: Array3f, d: Array3f, hit) -> Interaction:
        valid = Bool(hit.valid)
        prim = dr.select(valid, hit.prim, 0)
        t = hit.t
        p = o + d * t
        ng = Array3f(0.0, 0.0, 1.0)
        ns = Array3f(0.0, 0.0, 1.0)
        err = Float(0.0)
        uv = None
        if self.n_tri:
            is_tri = valid & (prim < self.n_tri)
            i = dr.select(is_tri, prim, 0)
            e1 = dr.gather(Array3f, self.e1, i, is_tri)
            e2 = dr.gather(Array3f, self.e2, i, is_tri)
            p0 = dr.gather(Array3f, self.p0, i, is_tri)
            u, v = hit.u, hit.v
            # Barycentric position is more accurate than o + t*d.
            pt, n, e = triangle_point(p0, e1, e2, u, v)
            p = dr.select(is_tri, pt, p)
            ng = dr.select(is_tri, n, ng)
            err = dr.select(is_tri, e, err)
            if self.has_normals:
                sn = (dr.gather(Array3f, self.n0, i, is_tri) * (1.0 - u - v)
                      + dr.gather(Array3f, self.n1, i, is_tri) * u
                      + dr.gather(Array3f, self.n2, i, is_tri) * v)
                len2 = dr.squared_norm(sn)
                sn = dr.select(len2 > 1e-20, sn * dr.rsqrt(len2), n)
                ns = dr.select(is_tri, sn, ns)
            else:
                ns = dr.select(is_tri, n, ns)
            if self.has_uv:
                uv = (dr.gather(Array2f, self.uv0, i, is_tri) * (1.0 - u - v)
                      + dr.gather(Array2f, self.uv1, i, is_tri) * u
                      + dr.gather(Array2f, self.uv2, i, is_tri) * v)
        if self.n_sph:
            is_sph = valid & (prim >= self.n_tri) & (prim < self.n_tri + self.n_sph)
            j = dr.select(is_sph, prim - self.n_tri, 0)
            c = dr.gather(Array3f, self.sph_c, j, is_sph)
            r = dr.gather(Float, self.sph_r, j, is_sph)
            n = dr.normalize(p - c)
            p = dr.select(is_sph, c + n * r, p)  # re-project onto the sphere
            ng = dr.select(is_sph, n, ng)
            ns = dr.select(is_sph, n, ns)
            err = dr.select(is_sph, sphere_error(p, r, n), err)
        if self.n_pl:
            first = self.n_tri + self.n_sph
            is_pl = valid & (prim >= first)
            k = dr.select(is_pl, prim - first, 0)
            n = dr.gather(Array3f, self.pl_n, k, is_pl)
            off = dr.gather(Float, self.pl_o, k, is_pl)
            p = dr.select(is_pl, plane_project(p, n, off), p)
            ng = dr.select(is_pl, n, ng)
            ns = dr.select(is_pl, n, ns)
            err = dr.select(is_pl, plane_error(p, n, off), err)
        material = dr.gather(UInt32, self.material, prim, valid)
        return Interaction(valid, t, p, ng, ns, prim, material, -d, uv, err)
