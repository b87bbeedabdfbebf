"""Surface interactions: what the integrator knows about a ray's hit.

:class:`SurfaceData` holds the per-primitive attributes on the device, in the
scene's original primitive order and in the accel's global id space
(triangles ``0..F-1``, spheres ``F..F+S-1``, planes ``F+S..F+S+P-1``).
:meth:`SurfaceData.interaction` turns an accel ``Hit`` into a
:class:`Interaction` (a :class:`TangentInteraction` where materials need
tangents). Only the primitive kinds the scene has are traced.

A triangle's attributes are one record of ``tri_data``, a multiple of 8 floats: ``p0``,
``e1``, ``e2``, then the three vertex normals, the three uvs and ``dp/du``, ``dp/dv``
where the scene has them, zero-padded. :meth:`SurfaceData.tri_fields` reads a record's
leading floats with Dr.Jit's packet gathers (8 floats per aligned load and a transpose,
``JitFlag.PacketOps``) rather than one gather per float; :meth:`SurfaceData.triangle` is
the one reader of the layout (the interactions, the emitters of
:mod:`~drpt.render.lights.area`, :meth:`SurfaceData.seen_from`). The array must be aligned
(:func:`~drpt.accel.device.device_array`): Dr.Jit reads an unaligned one by single
gathers.
"""

from __future__ import annotations

import drjit as dr
import numpy as np
from drjit.auto import Array2f, Array3f, ArrayXf, Bool, Float, UInt32

from ..accel.device import device_array
from ..accel.protocol import Hit
from ..backend import name as backend_name
from ..scene.model import Scene
from . import tables
from .spawn import plane_error, plane_project, plane_shift, sphere_error, triangle_point, triangle_shift
from .tables import Table, gather

#: a triangle's hit is moved along its plane to a point whose barycentrics are at most this
#: far outside it (:meth:`SurfaceData.seen_from`): past an edge, the plane of a coplanar
#: neighbour and, to first order, of a curved mesh's. A move past the diagonal of a floor far
#: from the origin is about 1e-3; a larger reach would let a ray grazing a wall move its hit
#: well past the wall's foot, off any surface (beyond it the lane keeps its spawned ray's hit)
TRIANGLE_REACH = 0.05

#: a sphere's hit is moved along its tangent plane (:meth:`SurfaceData.seen_from`) by at most
#: this fraction of the radius: the moved point is then off the sphere by ``|move|^2 / (2 r)``,
#: at most half this fraction of the move (the interaction projects it back)
SPHERE_SHIFT = 1e-2


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

    A Dr.Jit struct (``DRJIT_STRUCT``): ``dr.gather(type(si), si, index)``,
    ``dr.select``, ``dr.eval`` and symbolic loops take it whole. Every field is
    an array; ``uv`` and ``p_error`` default to zero (a width-1 broadcast, which a
    gather keeps a broadcast). ``dp_du`` and ``dp_dv`` are None here: only a
    :class:`TangentInteraction` carries them, so a scene whose materials need no
    tangent frame has none in its kernels.
    """

    DRJIT_STRUCT = {"valid": Bool, "t": Float, "p": Array3f, "ng": Array3f, "ns": Array3f,
                    "prim": UInt32, "material": UInt32, "wi": Array3f, "uv": Array2f, "p_error": Float}

    #: Mitsuba's dp/du and dp/dv: None (no tangent frame), see :class:`TangentInteraction`
    dp_du: Array3f | None = None
    dp_dv: Array3f | None = None

    def __init__(self, valid=None, t=None, p=None, ng=None, ns=None, prim=None, material=None, wi=None,
                 uv=None, p_error=None):
        # (no arguments: an empty struct for Dr.Jit to fill in, as dr.gather does)
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


class TangentInteraction(Interaction):
    """An :class:`Interaction` with Mitsuba's ``dp_du`` and ``dp_dv`` (world; its uv
    convention ``(u, 1 - v)``; zero: no tangent), made in scenes whose materials
    need a tangent frame (``MaterialTable.tangents``: anisotropic BSDFs, normal and
    bump maps; ``dp_dv`` stays zero unless a bump map needs it)."""

    DRJIT_STRUCT = {**Interaction.DRJIT_STRUCT, "dp_du": Array3f, "dp_dv": Array3f}

    def __init__(self, valid=None, t=None, p=None, ng=None, ns=None, prim=None, material=None, wi=None,
                 uv=None, p_error=None, dp_du=None, dp_dv=None):
        super().__init__(valid, t, p, ng, ns, prim, material, wi, uv, p_error)
        self.dp_du: Array3f = dp_du if dp_du is not None else Array3f(0.0)
        self.dp_dv: Array3f = dp_dv if dp_dv is not None else Array3f(0.0)


def triangle_tangents(positions: np.ndarray, uvs: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Mitsuba's ``dp/du`` and ``dp/dv`` of each triangle (``Mesh::compute_surface_interaction``),
    ``(F, 3)`` each: from the uvs (Mitsuba's convention ``(u, 1 - v)`` of drpt's) where
    their determinant is not 0, Mitsuba's ``coordinate_system`` of the face normal where
    it is, and the edges ``p1 - p0``, ``p2 - p0`` (the barycentric parameterisation)
    without uvs."""
    p = np.asarray(positions, np.float32).astype(np.float64)
    dp0, dp1 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    if uvs is None:
        return dp0, dp1
    uv = np.asarray(uvs, np.float32).astype(np.float64).copy()
    uv[..., 1] = 1.0 - uv[..., 1]
    duv0, duv1 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    det = duv0[:, 0] * duv1[:, 1] - duv0[:, 1] * duv1[:, 0]
    ok = det != 0.0
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)[:, None]
    dp_du = (duv1[:, 1:2] * dp0 - duv0[:, 1:2] * dp1) * inv
    dp_dv = (duv0[:, 0:1] * dp1 - duv1[:, 0:1] * dp0) * inv
    if not ok.all():
        n = np.cross(dp0[~ok], dp1[~ok])
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        s, t = coordinate_system(n)
        dp_du[~ok], dp_dv[~ok] = s, t
    return dp_du, dp_dv


def coordinate_system(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mitsuba's (and :class:`drpt.render.warp.Frame`'s) orthonormal basis of unit
    normals ``n`` ``(N, 3)`` (Duff et al. 2017), on the host."""
    sign = np.where(n[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    s = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], -1)
    t = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], -1)
    return s, t


class TriangleRecords:
    """Host copies of a few triangles' records (:meth:`SurfaceData.records`): ``ids`` and
    ``rows[j]`` the record of triangle ``ids[j]``, float32."""

    def __init__(self, ids: list[int], rows: np.ndarray):
        self.ids, self.rows = ids, rows


class TriangleRecord:
    """A triangle's data read by :meth:`SurfaceData.triangle`: corner ``p0`` and edges
    ``e1 = p1 - p0``, ``e2 = p2 - p0``; the vertex normals ``n`` and uvs ``uv`` (three
    each) and the tangents ``dp_du``, ``dp_dv`` where read, else None."""

    def __init__(self, p0: Array3f, e1: Array3f, e2: Array3f):
        self.p0, self.e1, self.e2 = p0, e1, e2
        self.n: tuple[Array3f, Array3f, Array3f] | None = None
        self.uv: tuple[Array2f, Array2f, Array2f] | None = None
        self.dp_du: Array3f | None = None
        self.dp_dv: Array3f | None = None


class SurfaceData:
    """``tangents``: 0, or 1 to give interactions Mitsuba's ``dp/du`` (anisotropic
    BSDFs and normal maps orient their frame by it), 2 to give ``dp/dv`` too (bump maps)."""

    def __init__(self, scene: Scene, with_uv: bool = False, tangents: int = 0):
        self.tangents = tangents
        tris, sph, pl = scene.triangles, scene.spheres, scene.planes
        self.n_tri, self.n_sph, self.n_pl = len(tris), len(sph), len(pl)
        if self.n_tri:
            # Edges of the float32 vertices the accelerators test, so that
            # p0 + u e1 + v e2 is rounded from a point of that triangle.
            p = np.asarray(tris.positions, np.float32).astype(np.float64)
            cols = [p[:, 0], p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]]
            self.has_normals = tris.normals is not None
            self.has_uv = with_uv and tris.uvs is not None
            if self.has_normals:
                cols += [tris.normals[:, k] for k in range(3)]
            if self.has_uv:
                cols += [tris.uvs[:, k] for k in range(3)]
            if tangents:
                dp_du, dp_dv = triangle_tangents(tris.positions, tris.uvs)
                cols += [dp_du] + ([dp_dv] if tangents > 1 else [])
            flat = np.concatenate([np.asarray(c, np.float32).reshape(self.n_tri, -1) for c in cols], 1)
            self.tri_floats = flat.shape[1]
            self.tri_rows = -(-self.tri_floats // 8)
            rec = np.zeros((self.n_tri, 8 * self.tri_rows), np.float32)
            rec[:, :self.tri_floats] = flat
            # aligned: Dr.Jit reads an unaligned array by one gather per float, not by packets
            self.tri_data = device_array(Float, rec)
        if self.n_sph:
            # (small tables: read as literals where they are few, drpt.render.tables)
            self.sph_c = Table(Array3f, sph.center)
            self.sph_r = Table(Float, sph.radius)
            self.sph_rot = None
            if tangents and sph.rotation is not None:
                rot = np.asarray(sph.rotation, np.float64)
                self.sph_rot = tuple(_vec(rot[:, :, k]) for k in range(3))  # columns: local axes
        if self.n_pl:
            self.pl_n = Table(Array3f, pl.normal)
            self.pl_o = Table(Float, pl.offset)
        mats = np.concatenate([tris.material, sph.material, pl.material]).astype(np.uint32)
        self.material = Table(UInt32, mats)

    def records(self, ids) -> TriangleRecords | None:
        """The records of the triangles ``ids`` (host copies: :meth:`triangle`'s ``among``),
        or None where they are more than :data:`drpt.render.tables.RUNS` or the backend is
        not LLVM (then their records are gathered). Read back from the uploaded records (an
        evaluation: call it while building, not while a kernel is traced)."""
        ids = [int(k) for k in ids]
        if not ids or len(ids) > tables.RUNS or backend_name() != "llvm" or not self.n_tri:
            return None
        n = self.tri_rows * 8
        at = np.repeat(np.asarray(ids, np.uint32) * n, n) + np.tile(np.arange(n, dtype=np.uint32), len(ids))
        rows = dr.gather(Float, self.tri_data, UInt32(at)).numpy().reshape(len(ids), n)
        return TriangleRecords(ids, rows)

    def tri_fields(self, i: UInt32, active: Bool, count: int,
                   among: TriangleRecords | None = None) -> list[Float]:
        """The first ``count`` floats of triangle ``i``'s record, read as packets of 8 (a
        32-byte load per lane and packet, where a gather per float reads one lane at a time),
        or with ``among`` (the records of the few triangles the lanes can hold,
        :meth:`records`) as compares and selects of their literals
        (:func:`drpt.render.tables.choose`): the same values."""
        if among is not None:
            return [tables.choose(i, among.ids, among.rows[:, k], active) for k in range(count)]
        out: list[Float] = []
        base = i * self.tri_rows
        for r in range(-(-count // 8)):
            row = dr.gather(ArrayXf, self.tri_data, base + r if r else base, active, shape=(8, dr.width(i)))
            out += [row[k] for k in range(8)]
        return out[:count]

    def triangle(self, i: UInt32, active: Bool, normals: bool = False, uv: bool = False,
                 tangents: int = 0, among: TriangleRecords | None = None) -> TriangleRecord:
        """Triangle ``i``'s data for the ``active`` lanes: always ``p0, e1, e2``; its three
        vertex normals with ``normals`` (None where the mesh has none), its three uvs with
        ``uv`` (None where the interactions carry none), ``dp/du`` with ``tangents`` >= 1 and
        ``dp/dv`` too with 2 (None beyond the tangents the record holds). Only the record's
        leading floats that these need are read; ``among``: the records of the few triangles
        the lanes can hold (:meth:`records`), read as literals."""
        n_off = 9
        uv_off = n_off + 9 * self.has_normals
        t_off = uv_off + 6 * self.has_uv
        tangents = min(tangents, self.tangents)
        count = 9
        if normals and self.has_normals:
            count = uv_off
        if uv and self.has_uv:
            count = t_off
        if tangents:
            count = t_off + 3 * tangents
        f = self.tri_fields(i, active, count, among)
        rec = TriangleRecord(*(Array3f(*f[k:k + 3]) for k in (0, 3, 6)))
        if normals and self.has_normals:
            rec.n = tuple(Array3f(*f[k:k + 3]) for k in range(n_off, uv_off, 3))
        if uv and self.has_uv:
            rec.uv = tuple(Array2f(*f[k:k + 2]) for k in range(uv_off, t_off, 2))
        if tangents:
            rec.dp_du = Array3f(*f[t_off:t_off + 3])
        if tangents > 1:
            rec.dp_dv = Array3f(*f[t_off + 3:t_off + 6])
        return rec

    # ------------------------------------------------------------------
    def seen_from(self, o: Array3f, d: Array3f, hit, p: Array3f):
        """``hit``, the closest hit of the ray ``(o, d)`` spawned from the surface point ``p``
        (``o``: ``p`` moved off its surface, :func:`drpt.render.spawn.origin`), as the
        parallel ray from ``p`` itself meets the same primitive: ``(origin, hit)`` for
        :meth:`interaction`, ``origin`` ``p`` and the hit's ``t`` from ``p`` (on a triangle its
        barycentrics moved with the point, :func:`~drpt.render.spawn.triangle_shift`). Exact
        on triangles and planes, to first order on spheres (along the tangent plane, then
        projected back). A point moved past its triangle's edge stays on that triangle's plane
        (within :data:`TRIANGLE_REACH`): exact where the neighbour is coplanar (a floor of two
        triangles), to first order on a curved mesh; at a silhouette, where the ray from ``p``
        would pass beside the mesh, the hit stays one it should not have, as the ray from
        ``o``'s did. A lane keeps ``o`` and its hit where the move is more than
        :data:`SPHERE_SHIFT` of its sphere's radius or the ray is parallel to the surface;
        the miss lanes too. The primitive is the hit's: a neighbour nearer ``p`` than the
        spawn offset is not looked for."""
        valid = Bool(hit.valid)
        prim = dr.select(valid, hit.prim, 0)
        delta = p - o  # (exact where p and o are close: no rounding of the coordinates' size)
        t, u, v = Float(hit.t), Float(hit.u), Float(hit.v)
        moved = Bool(False)
        if self.n_tri:
            is_tri = valid & (prim < self.n_tri)
            i = dr.select(is_tri, prim, 0)
            rec = self.triangle(i, is_tri)
            dt, du, dv = triangle_shift(rec.e1, rec.e2, delta, d)
            um, vm = u + du, v + dv
            # (a moved point past an edge stays on this triangle's plane: a coplanar
            # neighbour's point, and a curved mesh's to first order)
            near = dr.minimum(dr.minimum(um, vm), 1.0 - um - vm) > -TRIANGLE_REACH
            ok = is_tri & dr.isfinite(dt) & near
            t = dr.select(ok, t + dt, t)
            u = dr.select(ok, um, u)
            v = dr.select(ok, vm, v)
            moved |= ok
        if self.n_sph:
            is_sph = valid & (prim >= self.n_tri) & (prim < self.n_tri + self.n_sph)
            j = dr.select(is_sph, prim - self.n_tri, 0)
            c = gather(Array3f, self.sph_c, j, is_sph)
            r = gather(Float, self.sph_r, j, is_sph)
            dt, shift = plane_shift(delta, d, o + d * hit.t - c)
            ok = is_sph & dr.isfinite(dt) & (dr.squared_norm(shift) <= dr.square(r * SPHERE_SHIFT))
            t = dr.select(ok, t + dt, t)
            moved |= ok
        if self.n_pl:
            first = self.n_tri + self.n_sph
            is_pl = valid & (prim >= first)
            k = dr.select(is_pl, prim - first, 0)
            dt, _ = plane_shift(delta, d, gather(Array3f, self.pl_n, k, is_pl))
            ok = is_pl & dr.isfinite(dt)
            t = dr.select(ok, t + dt, t)
            moved |= ok
        return dr.select(moved, p, o), Hit(t, hit.prim, u, v, hit.valid)

    def interaction(self, o: Array3f, d: Array3f, hit) -> Interaction:
        valid = Bool(hit.valid)
        prim = dr.select(valid, hit.prim, 0)
        t = hit.t
        p = o + d * t
        ng = Array3f(0.0, 0.0, 1.0)
        ns = Array3f(0.0, 0.0, 1.0)
        err = Float(0.0)
        uv = None
        dp_du = Array3f(0.0) if self.tangents else None
        dp_dv = Array3f(0.0) if self.tangents > 1 else None
        if self.n_tri:
            is_tri = valid & (prim < self.n_tri)
            i = dr.select(is_tri, prim, 0)
            tri = self.triangle(i, is_tri, normals=True, uv=True, tangents=self.tangents)
            p0, e1, e2 = tri.p0, tri.e1, tri.e2
            u, v = hit.u, hit.v
            # Barycentric position is more accurate than o + t*d.
            pt, n, e = triangle_point(p0, e1, e2, u, v)
            p = dr.select(is_tri, pt, p)
            ng = dr.select(is_tri, n, ng)
            err = dr.select(is_tri, e, err)
            if tri.n is not None:
                sn = tri.n[0] * (1.0 - u - v) + tri.n[1] * u + tri.n[2] * v
                len2 = dr.squared_norm(sn)
                sn = dr.select(len2 > 1e-20, sn * dr.rsqrt(len2), n)
                ns = dr.select(is_tri, sn, ns)
            else:
                ns = dr.select(is_tri, n, ns)
            if tri.uv is not None:
                uv = tri.uv[0] * (1.0 - u - v) + tri.uv[1] * u + tri.uv[2] * v
            if tri.dp_du is not None:
                dp_du = dr.select(is_tri, tri.dp_du, dp_du)
            if tri.dp_dv is not None:
                dp_dv = dr.select(is_tri, tri.dp_dv, dp_dv)
        if self.n_sph:
            is_sph = valid & (prim >= self.n_tri) & (prim < self.n_tri + self.n_sph)
            j = dr.select(is_sph, prim - self.n_tri, 0)
            c = gather(Array3f, self.sph_c, j, is_sph)
            r = gather(Float, self.sph_r, j, is_sph)
            n = dr.normalize(p - c)
            p = dr.select(is_sph, c + n * r, p)  # re-project onto the sphere
            ng = dr.select(is_sph, n, ng)
            ns = dr.select(is_sph, n, ns)
            err = dr.select(is_sph, sphere_error(p, r, n), err)
            if self.tangents:
                # Mitsuba's sphere: dp/du = to_world (-y, x, 0) 2 pi of the local point (x, y, z)
                if self.sph_rot is None:
                    du = Array3f(-n.y, n.x, 0.0)
                else:
                    a0, a1, a2 = (dr.gather(Array3f, col, j, is_sph) for col in self.sph_rot)
                    lx, ly = dr.dot(a0, n), dr.dot(a1, n)
                    du = a1 * lx - a0 * ly
                dp_du = dr.select(is_sph, du * (r * 2.0 * dr.pi), dp_du)
        if self.n_pl:
            first = self.n_tri + self.n_sph
            is_pl = valid & (prim >= first)
            k = dr.select(is_pl, prim - first, 0)
            n = gather(Array3f, self.pl_n, k, is_pl)
            off = gather(Float, self.pl_o, k, is_pl)
            p = dr.select(is_pl, plane_project(p, n, off), p)
            ng = dr.select(is_pl, n, ng)
            ns = dr.select(is_pl, n, ns)
            err = dr.select(is_pl, plane_error(p, n, off), err)
        material = gather(UInt32, self.material, prim, valid)
        if self.tangents:
            return TangentInteraction(valid, t, p, ng, ns, prim, material, -d, uv, err, dp_du, dp_dv)
        return Interaction(valid, t, p, ng, ns, prim, material, -d, uv, err)
