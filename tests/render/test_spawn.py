"""Ray offsets from each hit's own rounding error (drpt/render/spawn.py).

Unit tests of the bounds: random triangles (well shaped, slivers, far from
the origin, large around it), spheres and planes at scales 1e-4 .. 1e8. Each
hit goes through :meth:`SurfaceData.interaction`, new rays leave it to both
sides at angles down to grazing (``cos`` from 1e-4 to 1), and

* the bound is conservative: ``p_error`` is at least ``p``'s distance from
  the float32 primitive (float64 arithmetic);
* the spawned origin lies strictly on the side the ray leaves toward;
* the same primitive tested again from there (the accelerators' tests) has
  no hit at ``t > 0`` (for a ray entering a sphere: none before the far side);
* the bound is tight: scaled by 1/16 it fails these checks on some hits, so
  it is within a factor 16 of the offset the float32 tests need, and it
  scales with the primitive's coordinates, not with anything else in the
  scene.

Render tests (Cornell box, small images, fixed seeds):

* a small sphere far out of view (x = 1e5, 1e6, 1e8) changes no pixel; the
  old offset, ``(max|p| + 1% of the scene's diagonal) * 2**-17``, darkened
  the box by 9-20% here (negative control);
* the box scaled by 1e-4 and 1e4 renders as the unscaled box with the same
  seed (mean within 2%, block z-test, no pixel darker by a z of 4);
* the box translated by 1e5 and 1e6 renders as the same float32 geometry at
  the origin (mean within 3%, no pixel darker by a z of 4); the old offset
  fails both (negative control);
* a closed cube or sphere around the camera with lights outside is exactly
  black at scales 1e-4 .. 1e8.
"""

from __future__ import annotations

import dataclasses

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array3f, Bool, Float, UInt32

from drpt.accel.protocol import INVALID, Hit
from drpt.geometry import intersect_plane, intersect_sphere, intersect_triangle_watertight
from drpt.options import RenderOptions
from drpt.render import spawn
from drpt.render.integrators.common import SHADOW_SHRINK, DirectLight, ShadowQuery, power_heuristic
from drpt.render.renderer import Renderer
from drpt.render.scene import DeviceScene
from drpt.render.surface import SurfaceData
from drpt.scene import load_scene
from drpt.scene.model import (
    DirectionalLight,
    Material,
    PerspectiveCamera,
    Planes,
    PointLight,
    Scene,
    Spheres,
    Triangles,
)
from drpt.testing import block_z

CAM = None  # SurfaceData ignores the camera
EPS = 2.0**-24
SCALES = (1e-4, 1.0, 1e4, 1e8)


def _a3(a) -> Array3f:
    a = np.asarray(a, np.float32)
    return Array3f(a[:, 0], a[:, 1], a[:, 2])


def _np(v) -> np.ndarray:
    return np.array(v, np.float64).T


def _unit(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _f32(a):
    return np.asarray(a, np.float32).astype(np.float64)


def _hit(t, hit, n, u=None, v=None):
    prim = dr.select(hit, dr.arange(UInt32, n), INVALID)
    return Hit(t, prim, u if u is not None else Float(0), v if v is not None else Float(0), hit)


class Spawned:
    """Hits of ``n`` random rays on one primitive each, and rays leaving them."""

    def __init__(self, scene, o, d, hit, rng):
        n = len(o)
        self.si = SurfaceData(scene).interaction(_a3(o), _a3(d), hit)
        self.valid = hit.valid.numpy()
        self.ng = _np(self.si.ng)
        self.p = _np(self.si.p)
        self.err = self.si.p_error.numpy().astype(np.float64)
        self.side = rng.choice([-1.0, 1.0], n)
        cos = 10.0 ** rng.uniform(-4, 0, n)
        t = _unit(rng, n)
        t -= self.ng * np.sum(t * self.ng, 1, keepdims=True)
        t /= np.linalg.norm(t, axis=1, keepdims=True)
        self.w = (self.side * cos)[:, None] * self.ng + np.sqrt(1 - cos**2)[:, None] * t
        self.cos = cos

    def origin(self, factor=1.0) -> Array3f:
        return spawn.origin(self.si.p, self.si.ng, self.si.p_error * factor, _a3(self.w))


def _triangles(kind, scale, n, rng):
    c = rng.uniform(-3, 3, (n, 1, 3))
    if kind == "local":  # triangles about as large as their distance to the origin
        return scale * (c + 0.5 * rng.normal(size=(n, 3, 3)))
    if kind == "far":  # small triangles far from the origin
        return scale * (c + 1e-3 * rng.normal(size=(n, 3, 3)))
    if kind == "origin":  # large triangles around the origin
        return scale * rng.normal(size=(n, 3, 3))
    # slivers: the third vertex 1e-3 .. 1 of the edge length off the first edge's line
    p0, e1 = scale * rng.normal(size=(n, 3)), scale * rng.normal(size=(n, 3))
    perp = _unit(rng, n)
    perp -= e1 * (np.sum(perp * e1, 1) / np.sum(e1 * e1, 1))[:, None]
    perp *= (np.linalg.norm(e1, axis=1) / np.linalg.norm(perp, axis=1) * 10 ** rng.uniform(-3, 0, n))[:, None]
    e2 = e1 * rng.uniform(-1, 1.5, (n, 1)) + perp
    return np.stack([p0, p0 + e1, p0 + e2], 1)


def _check_triangles(kind, scale, factor, n=20000, seed=0):
    """(hits, bound below the true error, origins on the wrong side, re-hits)."""
    rng = np.random.default_rng(seed)
    P = _triangles(kind, scale, n, rng)
    P32 = _f32(P)
    b = rng.dirichlet([1, 1, 1], n)
    b[: n // 4] **= 4  # a quarter of the hits near a vertex
    b /= b.sum(1, keepdims=True)
    d = _unit(rng, n)
    o = np.einsum("nk,nkc->nc", b, P32) - d * scale * rng.uniform(0.1, 3, (n, 1))
    p0, p1, p2 = _a3(P[:, 0]), _a3(P[:, 1]), _a3(P[:, 2])
    t, u, v, hit = intersect_triangle_watertight(_a3(o), _a3(d), p0, p1, p2, Float(np.inf))
    scene = Scene(path=None, camera=CAM, materials=[Material("m")],
                  triangles=Triangles(P, np.zeros(n, np.int32)))
    s = Spawned(scene, o, d, _hit(t, hit, n, u, v), rng)
    normal = np.cross(P32[:, 1] - P32[:, 0], P32[:, 2] - P32[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    so = s.origin(factor)
    with np.errstate(invalid="ignore"):  # missed lanes hold inf (only hits are counted below)
        true = np.abs(np.sum(normal * (s.p - P32[:, 0]), 1))
        above = np.sum(normal * (_np(so) - P32[:, 0]), 1) * np.sign(np.sum(normal * s.ng, 1))
    _, _, _, again = intersect_triangle_watertight(so, _a3(s.w), p0, p1, p2, Float(np.inf))
    h = s.valid
    return (h.sum(), (h & (s.err < true)).sum(), (h & ~(above * s.side > 0)).sum(),
            (h & again.numpy()).sum())


def _check_spheres(kind, scale, factor, n=20000, seed=0):
    rng = np.random.default_rng(seed)
    c = scale * rng.uniform(-3, 3, (n, 3))
    r = scale * rng.uniform(0.1, 2, n) * (1e-3 if kind == "far" else 1.0)
    c32, r32 = _f32(c), _f32(r)
    inside = rng.random(n) < 0.5
    d = _unit(rng, n)
    start_out = c32 - d * r32[:, None] * rng.uniform(1.5, 5, (n, 1)) + 0.5 * r32[:, None] * _unit(rng, n)
    o = np.where(inside[:, None], c32 + 0.5 * r32[:, None] * _unit(rng, n), start_out)
    cc, rr = _a3(c), Float(r.astype(np.float32))
    t, hit = intersect_sphere(_a3(o), _a3(d), cc, rr, Float(np.inf))
    scene = Scene(path=None, camera=CAM, materials=[Material("m")],
                  spheres=Spheres(c, r, np.zeros(n, np.int32)))
    s = Spawned(scene, o, d, _hit(t, hit, n), rng)
    true = np.abs(np.linalg.norm(s.p - c32, axis=1) - r32)
    so = s.origin(factor)
    above = np.linalg.norm(_np(so) - c32, axis=1) - r32
    t2, again = intersect_sphere(so, _a3(s.w), cc, rr, Float(np.inf))
    # A ray entering the sphere meets its far side at t ~ 2 r cos: only hits
    # before half of that are the surface it left.
    again = again.numpy() & ((s.side > 0) | (t2.numpy() < r32 * s.cos))
    h = s.valid
    return (h.sum(), (h & (s.err < true)).sum(), (h & ~(above * s.side > 0)).sum(), (h & again).sum())


def _check_planes(scale, factor, n=20000, seed=0):
    rng = np.random.default_rng(seed)
    normal, offset = _unit(rng, n), scale * rng.uniform(-3, 3, n)
    n32, off32 = _f32(normal), _f32(offset)
    d = _unit(rng, n)
    o = scale * rng.uniform(-5, 5, (n, 3))
    nn, oo = _a3(normal), Float(offset.astype(np.float32))
    t, hit = intersect_plane(_a3(o), _a3(d), nn, oo, Float(np.inf))
    scene = Scene(path=None, camera=CAM, materials=[Material("m")],
                  planes=Planes(normal, offset, np.zeros(n, np.int32)))
    s = Spawned(scene, o, d, _hit(t, hit, n), rng)
    h = s.valid
    true = np.where(h, np.abs(np.sum(n32 * np.where(h[:, None], s.p, 0), 1) - off32), 0)
    so = s.origin(factor)
    with np.errstate(invalid="ignore"):  # missed lanes hold inf (only hits are counted)
        above = np.sum(n32 * _np(so), 1) - off32
    _, again = intersect_plane(so, _a3(s.w), nn, oo, Float(np.inf))
    return (h.sum(), (h & (s.err < true)).sum(), (h & ~(above * s.side > 0)).sum(),
            (h & again.numpy()).sum())


CASES = ([("triangle", k) for k in ("local", "far", "origin", "sliver")]
         + [("sphere", k) for k in ("local", "far")] + [("plane", "")])


def _check(prim, kind, scale, factor):
    if prim == "triangle":
        return _check_triangles(kind, scale, factor)
    if prim == "sphere":
        return _check_spheres(kind, scale, factor)
    return _check_planes(scale, factor)


@pytest.mark.slow
@pytest.mark.parametrize("prim, kind", CASES)
def test_offset_origin_leaves_the_primitive(prim, kind):
    for scale in SCALES:
        hits, below, wrong_side, again = _check(prim, kind, scale, 1.0)
        assert hits > 5000
        assert (below, wrong_side, again) == (0, 0, 0), (scale, below, wrong_side, again)


@pytest.mark.slow
@pytest.mark.parametrize("prim, kind", CASES)
def test_offset_bound_is_within_a_factor_16_of_what_is_needed(prim, kind):
    # Negative control of the test above: a sixteenth of the bound is not
    # enough (for 0.1% .. 90% of the hits, depending on the case).
    for scale in (1e-4, 1e8):
        _, _, wrong_side, again = _check(prim, kind, scale, 1.0 / 16)
        assert wrong_side + again > 0, scale


def test_offset_bound_follows_the_primitive_not_the_scene():
    # A small triangle at the origin gets a bound of a few ulps of its own
    # coordinates, the same whether or not the scene also holds a large
    # triangle at 1e8 (which gets a few ulps of 1e8).
    small = np.array([[0.0, 0.0, 0.0], [1e-3, 0.0, 1e-4], [0.0, 1e-3, 2e-4]])
    errs = []
    for tris in ([small], [small, small * 1e7 + 1e8]):
        n = len(tris)
        s = Scene(path=None, camera=CAM, materials=[Material("m")],
                  triangles=Triangles(np.array(tris), np.zeros(n, np.int32)))
        o = np.array([[3e-4, 3e-4, 1.0], [4e11, 4e11, 1e8 + 1e3]])[:n]
        d = np.array([[0.0, 0.0, -1.0]] * n)
        hit = Hit(Float([1.0] * n), UInt32(list(range(n))), Float([0.3] * n), Float([0.3] * n),
                  dr.full(Bool, True, n))
        errs.append(SurfaceData(s).interaction(_a3(o), _a3(d), hit).p_error.numpy())
    assert errs[0][0] == errs[1][0]
    assert 0 < errs[0][0] < 64 * EPS * 1e-3
    assert 0 < errs[1][1] < 64 * EPS * 1e8


# ------------------------------------------------------------------- renders
def _render(scene, size=24, spp=16, seed=3):
    return Renderer(scene, RenderOptions(width=size, height=size, spp=spp, seed=seed, progress=False)).render()


def _with_far_sphere(scene, x):
    return dataclasses.replace(scene, spheres=Spheres(np.array([[x, 0.0, 0.0]]), np.array([0.5]),
                                                      np.zeros(1, np.int32)))


def _scene_size_offset(monkeypatch, scene):
    """The offset drpt had before: ``(max|p| + 1% of the scene's diagonal) *
    2**-17``, with the shadow ray toward an area light along the direction
    from the unmoved shading point."""
    lo, hi = scene.bounds()
    floor = 0.01 * float(np.linalg.norm(hi - lo))

    def spawn_old(self, si, d):
        mag = (dr.max(dr.abs(si.p)) + floor) * 2.0**-17
        return si.p + si.ng * dr.mulsign(mag, dr.dot(si.ng, d))

    def query_old(self, si, es, f, pdf_b, mis, coherent):
        # every next-event estimate's shadow query (DirectLight.emitter, emitter_query and
        # emitter_query_sample all build theirs here), along the unmoved point's direction
        ok = es.valid & (dr.max(f) > 0.0)
        so = self.scene.spawn(si, es.wo)
        w = power_heuristic(es.pdf, pdf_b) if mis else Float(1.0)
        return ShadowQuery(f * es.le * (w / es.pdf), so, es.wo, dr.norm(es.p - so) * SHADOW_SHRINK, ok, coherent)

    monkeypatch.setattr(DeviceScene, "spawn", spawn_old)
    monkeypatch.setattr(DirectLight, "_query", query_old)


def _moved(scene, scale=1.0, shift=0.0, quantize=False):
    """The scene's triangles and camera scaled, then shifted by ``shift`` on
    every axis; ``quantize``: shifted back after rounding to float32 (the
    same float32 geometry, at the origin)."""
    p = scene.triangles.positions * scale + shift
    c = np.asarray(scene.camera.center, float) * scale + shift
    if quantize:
        p, c = _f32(p) - shift, _f32(c) - shift
    return dataclasses.replace(scene, triangles=dataclasses.replace(scene.triangles, positions=p),
                               camera=dataclasses.replace(scene.camera, center=tuple(c)))


def _dark_pixels(r, ref, z=-4.0):
    """Pixels darker than the reference by more than 4 combined standard errors
    (acne: samples that hit their own surface again and lose their light)."""
    d = r.image.mean(2) - ref.image.mean(2)
    return int((d < z * np.sqrt(r.variance.mean(2) + ref.variance.mean(2) + 1e-30)).sum())


@pytest.mark.slow
def test_far_sphere_changes_nothing(cornell):
    box = load_scene(cornell)
    ref = _render(box).image
    for x in (1e5, 1e6, 1e8):
        img = _render(_with_far_sphere(box, x)).image
        assert np.array_equal(img, ref), x  # same passes, same accelerator: bit-identical


@pytest.mark.slow
def test_far_sphere_negative_control_scene_size_offset(monkeypatch, cornell):
    box = load_scene(cornell)
    ref = _render(box).image.mean()
    far = _with_far_sphere(box, 1e6)
    _scene_size_offset(monkeypatch, far)
    assert _render(far).image.mean() < 0.95 * ref


@pytest.mark.slow
@pytest.mark.parametrize("scale", [1e-4, 1e4])
def test_scaled_box_renders_the_same(scale, cornell):
    # Radiance does not depend on scale. Same seed, so the tolerances are
    # tighter than independent noise: mean within 2%, block z < 4.5 (8x8
    # blocks, as drpt.testing.block_z), no pixel darker by a z of 4.
    box = load_scene(cornell)
    ref = _render(box, 32, 32)
    r = _render(_moved(box, scale), 32, 32)
    assert abs(r.image.mean() / ref.image.mean() - 1) < 0.02
    assert np.abs(block_z(r.image, r.variance, ref.image, ref.variance)).max() < 4.5
    assert _dark_pixels(r, ref) == 0


def _low_light_box(cornell):
    """The Cornell box with its light 0.5 below the ceiling instead of 0.001,
    so that at 1e6 (float32 spacing 0.0625) light and ceiling stay apart."""
    box = load_scene(cornell)
    emissive = np.array([m.is_emissive for m in box.materials])[box.triangles.material]
    p = box.triangles.positions.copy()
    p[emissive, :, 1] -= 0.5
    return dataclasses.replace(box, triangles=dataclasses.replace(box.triangles, positions=p))


@pytest.mark.slow
@pytest.mark.parametrize("shift", [1e5, 1e6])
def test_translated_box_renders_as_at_the_origin(shift, cornell):
    # At 1e6 float32 coordinates are 0.0625 apart and the offsets are a few
    # of those (~0.2, 4% of the box), so contact shadows and corners change
    # within that band: the mean stays within 3% of the same float32 geometry
    # rendered at the origin (same seed; 1.3% measured), and no pixel is
    # darker by a z of 4.
    box = _low_light_box(cornell)
    ref = _render(_moved(box, shift=shift, quantize=True), 32, 32)
    r = _render(_moved(box, shift=shift), 32, 32)
    assert r.nonfinite == 0
    assert abs(r.image.mean() / ref.image.mean() - 1) < 0.03
    assert _dark_pixels(r, ref) == 0


@pytest.mark.slow
def test_translated_box_negative_control_scene_size_offset(monkeypatch, cornell):
    box = _low_light_box(cornell)
    ref = _render(_moved(box, shift=1e6, quantize=True), 32, 32)
    moved = _moved(box, shift=1e6)
    _scene_size_offset(monkeypatch, moved)
    r = _render(moved, 32, 32)
    assert abs(r.image.mean() / ref.image.mean() - 1) > 0.03
    assert _dark_pixels(r, ref) > 10


def _cube(scale):
    """Twelve triangles of a closed cube of half-size ``scale`` around the
    origin (shared vertices, outward winding)."""
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    faces = [f for a, b, c, d in quads for f in ((a, b, c), (a, c, d))]
    return v[np.array(faces)] * scale


@pytest.mark.slow
@pytest.mark.parametrize("enclosure", ["cube", "sphere"])
def test_closed_enclosure_lets_no_light_in(enclosure):
    # The camera inside, looking at a corner of the cube (or the sphere's
    # wall); a point light, a directional light and an emissive triangle
    # outside. Any leak through the wall, its edges or corners is light.
    # Scaled, not translated: far from the origin a hit that rounds onto an
    # edge lies on the adjacent face's plane, which no offset along the
    # normal fixes, and light leaks there (see drpt/render/spawn.py).
    for scale in (1e-4, 1.0, 1e4, 1e8):
        mats = [Material("wall", kd=(0.8, 0.8, 0.8)), Material("light", emission=(50.0, 50.0, 50.0))]
        light = np.array([[[-3, 3, -3], [3, 3, -3], [0, 3, 3]]], float) * scale
        if enclosure == "cube":
            tris = np.concatenate([_cube(scale), light])
            spheres = Spheres.empty()
        else:
            tris = light
            spheres = Spheres(np.zeros((1, 3)), np.array([scale]), np.zeros(1, np.int32))
        material = np.zeros(len(tris), np.int32)
        material[-1] = 1
        cam = PerspectiveCamera(tuple(np.full(3, -0.5 * scale)), (1, 1, 1), (0, 1, 0), 60.0)
        scene = Scene(path=None, camera=cam, materials=mats,
                      triangles=Triangles(tris, material), spheres=spheres,
                      lights=[PointLight((0.0, 2.0 * scale, 0.0), (10 * scale**2,) * 3),
                              DirectionalLight((-1.0, -2.0, -0.5), (1.0, 1.0, 1.0))])
        img = _render(scene, 16, 16).image
        assert np.all(img == 0.0), (scale, float(img.max()))
