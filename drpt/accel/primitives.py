"""The scene's primitives on the device and the per-primitive tests that
every accelerator's loop calls.

:class:`SceneGeometry` holds the primitive counts, the planes (unbounded:
every accelerator tests them by brute force, before its traversal, so that a
near plane already shortens it) and, once :meth:`SceneGeometry.upload_primitives`
ran, the triangle and sphere buffers, in the scene's order (grid, brute
force) or in a BVH's order (with the map back to scene ids). It also starts
the BVH kinds' queries (:meth:`~SceneGeometry.begin_query`) and turns every
accelerator's best hit into a :class:`~drpt.accel.protocol.Hit`
(:meth:`~SceneGeometry.hit`).

Buffers (float32): triangle vertices ``p0, p1, p2`` as ``9 * F`` floats
(:func:`triangle_buffer`; vertices, not edges, because the watertight test
needs bitwise identical shared vertices, see :mod:`drpt.geometry.triangle`;
the 4-wide BVH pads each vertex to 4 floats, :mod:`drpt.accel.bvh4`), spheres
as ``4 * S`` floats ``[c.xyz, r]`` (:func:`sphere_buffer`). When a BVH mixes
triangles and spheres, a per-position uint32 code ``local | is_sphere << 31``
selects the test (:func:`leaf_orders`, :func:`leaf_primitive`). Code for
absent primitive kinds is not traced at all.
"""

from __future__ import annotations

import drjit as dr
import numpy as np
from drjit.auto import Array3f, Array4f, Bool, Float, UInt32

from ..geometry.plane import intersect_plane
from ..geometry.sphere import intersect_sphere
from ..geometry.triangle import RayPrep, watertight_permuted
from .device import device_array, nbytes
from .protocol import INVALID, Hit
from .tree import round_down_f32, round_up_f32


def triangle_buffer(positions: np.ndarray) -> np.ndarray:
    """``(F, 3, 3)`` positions -> flat float32 ``[p0, p1, p2]`` per triangle."""
    return np.ascontiguousarray(np.asarray(positions, np.float32).reshape(-1))


def sphere_buffer(center: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Centers and radii -> flat float32 ``[c.xyz, r]`` per sphere."""
    c = np.asarray(center, np.float32)
    r = np.asarray(radius, np.float32)[:, None]
    return np.ascontiguousarray(np.concatenate([c, r], 1).reshape(-1))


class SceneGeometry:
    """Device copies shared by the accelerators: counts, planes and (after
    :meth:`upload_primitives`) the triangle and sphere buffers.

    Attributes:
        F, S, P: triangle, sphere and plane counts; ``N = F + S``.
        tri_buf, sph_buf: primitive buffers (``None`` when absent).
        codes: per-position primitive codes of a mixed BVH order, else ``None``.
        prim_ids: BVH position -> scene id (``None`` in the scene's order).
        host_sizes: entries of each uploaded buffer (without padding).
    """

    def __init__(self, scene):
        self.F = len(scene.triangles)
        self.S = len(scene.spheres)
        self.P = len(scene.planes)
        self.N = self.F + self.S
        if self.P:
            n = np.asarray(scene.planes.normal, np.float32)
            self.plane_n = Array3f(n[:, 0], n[:, 1], n[:, 2])
            self.plane_o = Float(np.asarray(scene.planes.offset, np.float32))
        else:
            self.plane_n = self.plane_o = None
        self.tri_buf = self.sph_buf = self.codes = self.prim_ids = None
        self.host_sizes = {}

    def upload_primitives(self, scene, order: np.ndarray | None = None,
                          triangles=triangle_buffer, padded: bool = False) -> None:
        """Upload the triangles (in the layout ``triangles(positions)``) and
        spheres, in the scene's order, or in the BVH order ``order``
        (position -> scene id of triangles and spheres, :func:`leaf_orders`),
        with :func:`~drpt.accel.device.device_array` (``padded`` as there)."""
        F, S = self.F, self.S
        tris, sph = scene.triangles.positions, (scene.spheres.center, scene.spheres.radius)
        codes = None
        if order is not None:
            self.prim_ids = self._up("prim_ids", UInt32, order.astype(np.uint32), padded)
            tri_order, sph_order, codes = leaf_orders(order, F)
            if F:
                tris = tris[tri_order]
            if S:
                sph = (sph[0][sph_order], sph[1][sph_order])
        if F:
            self.tri_buf = self._up("tri_buf", Float, triangles(tris), padded)
        if S:
            self.sph_buf = self._up("sph_buf", Float, sphere_buffer(*sph), padded)
        if codes is not None:
            self.codes = self._up("codes", UInt32, codes, padded)

    def _up(self, name, cls, a, padded):
        self.host_sizes[name] = a.size
        return device_array(cls, a, padded)

    def nbytes(self) -> int:
        """Device bytes of the primitive buffers and planes."""
        return nbytes(self.prim_ids, self.tri_buf, self.sph_buf, self.codes) + 16 * self.P

    def intersect_planes(self, o, d, bt, bj, any_hit: bool):
        """Test all planes; return updated ``(bt, bj)`` with ``bj = N + k``."""
        if not self.P:
            return bt, bj
        pn, po, N, P = self.plane_n, self.plane_o, self.N, self.P

        def cond(k, bt, bj):
            return k < P

        def body(k, bt, bj):
            n = dr.gather(Array3f, pn, k)
            off = dr.gather(Float, po, k)
            t, h = intersect_plane(o, d, n, off, bt)
            bt = dr.select(h, t, bt)
            bj = dr.select(h, N + k, bj)
            return k + 1, bt, bj

        _, bt, bj = dr.while_loop((UInt32(0), bt, bj), cond, body, label="drpt_planes")
        return bt, bj

    def begin_query(self, o, d, tmax, active, any_hit: bool):
        """Start of the BVH kinds' queries: the rays as arrays, the planes
        tested brute force, the best hit so far ``bt, bj, bu, bv``, and
        ``active`` without the rays an any-hit query has already answered."""
        o = Array3f(o)
        d = Array3f(d)
        active = Bool(active)
        bt = dr.select(active, Float(tmax), 0.0)
        bj = UInt32(INVALID)
        bt, bj = self.intersect_planes(o, d, bt, bj, any_hit)
        if any_hit:
            active &= bj == INVALID
        return o, d, active, bt, bj, Float(0), Float(0)

    def hit(self, bt, bj, bu, bv) -> Hit:
        """The :class:`~drpt.accel.protocol.Hit` of a query's best hit
        ``(bt, bj, bu, bv)``, ``bj`` a position in this geometry's order."""
        valid = bj != INVALID
        if self.prim_ids is not None:
            in_bvh = valid & (bj < self.N)
            prim = dr.select(in_bvh, dr.gather(UInt32, self.prim_ids, bj, in_bvh), bj)
        else:
            prim = bj
        return Hit(dr.select(valid, bt, float("inf")), prim, bu, bv, valid)


def test_triangle(tri_buf, idx, prep: RayPrep, bt, active):
    """Watertight test of triangle ``idx`` of a flat vertex buffer."""
    base = idx * 9
    g = [
        dr.gather(Float, tri_buf, base + (3 * v) + k, active)
        for v in range(3)
        for k in (prep.kx, prep.ky, prep.kz)
    ]
    t, u, v, h = watertight_permuted(prep, *g, bt)
    return t, u, v, h & active


def test_sphere(sph_buf, idx, o, d, bt, active):
    """Sphere ``idx`` of ``sph_buf`` (center and radius as 4 floats) against the rays:
    ``(t, hit)`` of the nearest intersection before ``bt``, ``hit`` only where ``active``."""
    s = dr.gather(Array4f, sph_buf, idx, active)
    t, h = intersect_sphere(o, d, Array3f(s.x, s.y, s.z), s.w, bt)
    return t, h & active


def nearest_primitive(tri_buf, sph_buf, tri_idx, sph_idx, prim, prep: RayPrep, o, d,
                      tri_on, sph_on, bt, bj, bu, bv, tri_test=None):
    """Test one triangle (lanes ``tri_on``) and/or one sphere (``sph_on``) and
    keep the nearer hit: returns the updated closest-hit record
    ``(bt, bj, bu, bv)`` (``bj = prim`` where a hit was kept) and ``hit_any``.
    Absent buffers trace no code. Shared by every accelerator's loop;
    ``tri_test`` reads the triangle buffer's layout (default
    :func:`test_triangle`, looked up at call time)."""
    hit_any = Bool(False)
    if tri_buf is not None:
        t, u, v, h = (tri_test or test_triangle)(tri_buf, tri_idx, prep, bt, tri_on)
        bt = dr.select(h, t, bt)
        bj = dr.select(h, prim, bj)
        bu = dr.select(h, u, bu)
        bv = dr.select(h, v, bv)
        hit_any |= h
    if sph_buf is not None:
        t, h = test_sphere(sph_buf, sph_idx, o, d, bt, sph_on)
        bt = dr.select(h, t, bt)
        bj = dr.select(h, prim, bj)
        bu = dr.select(h, 0.0, bu)
        bv = dr.select(h, 0.0, bv)
        hit_any |= h
    return bt, bj, bu, bv, hit_any


def leaf_primitive(codes, pi, pa):
    """Buffer index and lane masks (triangle, sphere) of BVH position ``pi``
    (lanes ``pa``): the position itself when the scene has one primitive kind,
    else decoded from ``codes`` (``local index | sphere << 31``,
    :func:`leaf_orders`)."""
    if codes is None:
        return pi, pa, pa
    code = dr.gather(UInt32, codes, pi, pa)
    sph = (code >> 31) != 0
    return code & 0x7FFFFFFF, pa & ~sph, pa & sph


def primitive_bounds(scene, F: int, S: int) -> tuple[np.ndarray, np.ndarray]:
    """Float32 boxes, rounded outward, of a scene's ``F`` triangles then ``S``
    spheres (BVH primitive ids ``0..F+S-1``); spheres padded against round-off."""
    los, his = [], []
    if F:
        p32 = np.asarray(scene.triangles.positions, np.float32)
        # elementwise over the three vertices (a reduction over the middle
        # axis of (F, 3, 3) is much slower in numpy); min/max of float32 are exact
        los.append(np.minimum(np.minimum(p32[:, 0], p32[:, 1]), p32[:, 2]).astype(np.float64))
        his.append(np.maximum(np.maximum(p32[:, 0], p32[:, 1]), p32[:, 2]).astype(np.float64))
    if S:
        c = np.asarray(scene.spheres.center, np.float64)
        r = np.abs(np.asarray(scene.spheres.radius, np.float64))[:, None]
        pad = r * 1e-5 + np.abs(c) * 1e-6
        los.append(c - r - pad)
        his.append(c + r + pad)
    return round_down_f32(np.concatenate(los)), round_up_f32(np.concatenate(his))


def leaf_orders(order: np.ndarray, F: int):
    """From the BVH's primitive order (position -> primitive id): the order of
    the triangle buffer, of the sphere buffer, and for scenes with both, the
    per-position code ``local index | sphere << 31`` (else None)."""
    is_sph = order >= F
    tri_order = order[~is_sph]
    sph_order = order[is_sph] - F
    codes = None
    if tri_order.size and sph_order.size:
        local = np.empty(order.size, np.int64)
        local[~is_sph] = np.arange(tri_order.size)
        local[is_sph] = np.arange(sph_order.size)
        codes = (local | (is_sph.astype(np.int64) << 31)).astype(np.uint32)
    return tri_order, sph_order, codes

