"""The AOV kernel: first-hit quantities of camera rays (:mod:`drpt.aovs` names them).

:func:`aov_values` traces rays ``(o, d)`` to their first hit and returns the AOVs'
channels as a list of ``Float`` (0 on a miss, as Mitsuba's ``aov`` integrator zeroes a
missed interaction). The denoiser's guides (``guide_albedo``, ``guide_normal``) follow
delta lobes (mirror, glass: one sampled lobe per bounce, at most :data:`MAX_DELTA`
bounces) to the first other surface first. The renderer traces this kernel once per pass
beside the beauty kernel, only for renders that ask for AOVs or denoising.
"""

from __future__ import annotations

import drjit as dr
from drjit.auto import PCG32, Array2f, Array3f, Bool, Float, UInt32

from ..aovs import GUIDES
from ..errors import DrptError
from .loops import loops_once
from .tables import gather

#: the most delta bounces a guide ray follows before it takes the surface it is on
MAX_DELTA = 8


@loops_once
@dr.syntax
def _past_delta(scene, rng: PCG32, o: Array3f, d: Array3f) -> tuple[Array3f, Array3f]:
    """The ray, per lane, whose first hit is the first non-delta surface (or a miss)
    along the path that follows delta lobes from ``(o, d)``."""
    n = max(dr.width(o), dr.width(d))  # a pinhole's origin may be one value for all lanes
    active = dr.full(Bool, True, n)
    depth = dr.zeros(UInt32, n)
    o, d = o + dr.zeros(Array3f, n), d + dr.zeros(Array3f, n)  # loop state starts full width
    while active:
        si = scene.intersect(o, d, active)
        u1 = rng.next_float32()
        u2 = Array2f(rng.next_float32(), rng.next_float32())
        follow = active & si.valid & scene.is_delta(si) & (depth < MAX_DELTA)
        wo, bs = scene.sample_bsdf(si, u1, u2)
        follow &= bs.valid
        o[follow] = scene.spawn(si, wo)
        d[follow] = wo
        depth += 1
        active = Bool(follow)
    return o, d


def aov_values(scene, rng: PCG32, o: Array3f, d: Array3f, kinds, ids=None,
               near=None) -> list[Float]:
    """The channels of the AOV ``kinds`` (in order) for rays ``(o, d)``. ``ids``: for
    ``shape_index`` and ``prim_index``, ``(shape, prim)`` per global primitive id
    (:func:`index_arrays`). ``near``: ``(near_clip, unit forward)`` of a perspective camera
    whose rays Mitsuba starts on its near plane: ``depth`` is measured from there."""
    prelim = scene.intersect_preliminary(o, d, Bool(True))
    si = scene.interaction(o, d, prelim)
    hit = si.valid
    out: list[Float] = []

    def vec(v, n=3):
        out.extend(dr.select(hit, v[i], 0.0) for i in range(n))

    gsi = None
    if any(k in GUIDES for k in kinds) and _has_delta(scene):
        go, gd = _past_delta(scene, rng, o, d)
        gsi = scene.intersect(go, gd, Bool(True))
    for kind in kinds:
        if kind == "albedo":
            vec(scene.albedo(si, hit))
        elif kind == "depth":
            t = si.t
            if near is not None:
                t = t - near[0] / dr.dot(d, Array3f(*near[1]))
            out.append(dr.select(hit, t, 0.0))
        elif kind == "position":
            vec(si.p)
        elif kind == "uv":
            vec(_uv(scene, si, prelim), 2)
        elif kind == "geo_normal":
            vec(si.ng)
        elif kind == "sh_normal":
            vec(si.ns)
        elif kind in ("shape_index", "prim_index"):
            table = ids[0] if kind == "shape_index" else ids[1]
            out.append(dr.select(hit, Float(dr.gather(UInt32, table, si.prim, hit)), 0.0))
        elif kind in GUIDES:
            g = si if gsi is None else gsi
            v = scene.albedo(g, g.valid) if kind == "guide_albedo" else g.ns
            out.extend(dr.select(g.valid, v[i], 0.0) for i in range(3))
        else:
            raise ValueError(f"unknown AOV kind {kind!r}")
    return out


def index_arrays(model) -> tuple[UInt32, UInt32]:
    """``(shape, prim)`` per global primitive id (triangles, spheres, planes) of a scene
    model read from Mitsuba XML (:attr:`drpt.scene.model.Triangles.shape_index`); a
    :class:`~drpt.errors.DrptError` for other scenes."""
    import numpy as np

    tri, sph, pl = model.triangles, model.spheres, model.planes
    if (len(tri) and tri.shape_index is None) or (len(sph) and sph.shape_index is None) or len(pl):
        raise DrptError("the prim_index and shape_index AOVs need a Mitsuba XML scene (drpt's "
                        "text format has no shapes)")
    shape = np.concatenate([tri.shape_index if len(tri) else np.zeros(0, np.int32),
                            sph.shape_index if len(sph) else np.zeros(0, np.int32), [0]])
    prim = np.concatenate([tri.prim_index if len(tri) else np.zeros(0, np.int32),
                           np.zeros(len(sph) + 1, np.int32)])
    return UInt32(shape.astype(np.uint32)), UInt32(prim.astype(np.uint32))


def _uv(scene, si, prelim) -> Array2f:
    """Mitsuba's ``si.uv``: ``(u, 1 - v)`` of a triangle's OBJ-convention uv, or where no
    triangle of the scene has uvs the hit's barycentric coordinates ``(b1, b2)`` (Mitsuba's
    for a mesh without texture coordinates); on a sphere ``(phi / 2 pi, theta / pi)`` of
    the direction from its center (world axes: the frame of a sphere given by center and
    radius)."""
    surf = scene.surfaces
    n_tri, n_sph = getattr(surf, "n_tri", 0), getattr(surf, "n_sph", 0)
    if getattr(surf, "has_uv", False):
        uv = Array2f(si.uv.x, 1.0 - si.uv.y)
    elif n_tri:
        uv = dr.select(si.valid & (si.prim < n_tri), Array2f(prelim.u, prelim.v), Array2f(0.0))
    else:
        uv = Array2f(0.0)
    if n_sph:
        is_sph = si.valid & (si.prim >= n_tri) & (si.prim < n_tri + n_sph)
        c = gather(Array3f, surf.sph_c, dr.select(is_sph, si.prim - n_tri, 0), is_sph)
        v = dr.normalize(si.p - c)
        phi = dr.atan2(v.y, v.x)
        phi = dr.select(phi < 0.0, phi + 2.0 * dr.pi, phi)
        theta = dr.acos(dr.clip(v.z, -1.0, 1.0))
        uv = dr.select(is_sph, Array2f(phi * (0.5 / dr.pi), theta / dr.pi), uv)
    return uv


def _has_delta(scene) -> bool:
    """Whether some material has a delta lobe (else guides are the first hit's)."""
    return bool(getattr(scene.materials, "_any_delta", False))
