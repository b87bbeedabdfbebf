"""The parallelogram test (drpt.geometry.parallelogram) against the two watertight
triangle tests it replaces in the inline accelerator: which pairs it takes, the same hits
within float rounding, and rays leaving its surface that do not hit it again."""

from __future__ import annotations

import drjit as dr
import numpy as np
from drjit.auto import Array3f, Bool, Float

import drpt.geometry.parallelogram as pg
from drpt.accel import InlineList
from drpt.geometry.parallelogram import parallelogram_pairs
from drpt.render.spawn import origin, triangle_point
from support.accel import hits, make_scene, rays

#: Mitsuba's rectangle mesh: corners (-1,-1), (1,-1), (1,1), (-1,1), faces (0,1,2), (2,3,0)
CORNERS = np.float64([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]])
FACES = [(0, 1, 2), (2, 3, 0)]


def rectangles(rng, count: int, gap: float = 4.0) -> np.ndarray:
    """``count`` separate rectangles (random affine maps of Mitsuba's), ``(2 count, 3, 3)``."""
    out = []
    for k in range(count):
        m = rng.normal(size=(3, 3)) * rng.uniform(0.3, 3.0)
        c = CORNERS @ m.T + [gap * k, rng.normal(), rng.normal()]
        out += [c[list(f)] for f in FACES]
    return np.asarray(out)


def both(scene, o, d, tmax=np.inf, monkeypatch=None):
    quad = hits(InlineList(scene), o, d, tmax)
    monkeypatch.setattr(InlineList, "parallelograms", False)
    tri = hits(InlineList(scene), o, d, tmax)
    monkeypatch.undo()
    return quad, tri


def test_pairs_only_separate_parallelograms():
    """Pairs: separate parallelograms only (no shared outer edge, no other surface touching
    their plane, consecutive triangles); the controls are the same rectangles paired where
    those conditions hold."""
    rng = np.random.default_rng(1)
    rects = rectangles(rng, 3)
    assert [q.first for q in parallelogram_pairs(rects)] == [0, 2, 4]
    # a trapezoid is two triangles but no parallelogram
    trap = CORNERS.copy()
    trap[2, 0] = 2.0
    assert parallelogram_pairs(np.stack([trap[list(f)] for f in FACES])) == []
    # two rectangles sharing an edge (a Cornell box's walls): the shared edge must stay
    # watertight, so neither is taken; the pairs after them still are
    side = CORNERS + [2, 0, 0]
    shared = np.stack([CORNERS[list(f)] for f in FACES] + [side[list(f)] for f in FACES])
    assert [q.first for q in parallelogram_pairs(np.concatenate([shared, rects]))] == [4, 6, 8]
    # triangles not consecutive in the list are not paired
    assert parallelogram_pairs(rects[[0, 2, 1, 3]]) == []
    # a floor with a triangle standing on it (a vertex in its plane): ties between the two
    # are float rounding, so the floor stays two triangles; lifted off the plane by 1e-3,
    # it is paired again
    floor = np.stack([CORNERS[list(f)] for f in FACES]) * 5
    standing = np.float64([[[0, 0, 0], [1, 0, 1], [0, 1, 1]]])
    assert parallelogram_pairs(np.concatenate([floor, standing])) == []
    assert [q.first for q in parallelogram_pairs(np.concatenate([floor, standing + [0, 0, 1e-3]]))] == [0]


def test_same_hits_as_the_triangle_tests(monkeypatch):
    """Rays at random rectangles: the same hits and misses except within float rounding of an
    edge, the same distance and barycentrics of the same triangle except within rounding of
    the diagonal (where either triangle is right). Where a ray grazes the plane its distance
    is ill-conditioned in both tests: a few in 1e4 differ by more than 1e-5 relative."""
    rng = np.random.default_rng(2)
    tris = rectangles(rng, 5)
    sc = make_scene(tris, (rng.random((2, 3)) * 10, rng.random(2) + 0.2))
    assert len(InlineList(sc).quads) == 5
    R = 40000
    target = tris[rng.integers(0, len(tris), R)]
    w = rng.dirichlet([1, 1, 1], R) * rng.uniform(0.9, 1.1, (R, 1))  # some just outside
    aim = np.einsum("rk,rkc->rc", w, target)
    o = aim + rng.normal(size=(R, 3)) * 6
    d = aim - o
    tmax = np.where(rng.random(R) < 0.3, rng.uniform(0.5, 1.5, R), np.inf)
    (t, prim, u, v, valid, occ), (t2, prim2, u2, v2, valid2, occ2) = both(sc, o, d, tmax, monkeypatch)
    assert valid.mean() > 0.5 and (prim[valid] >= 10).any() and (prim[valid] % 2 == 1).any()
    assert (valid != valid2).mean() < 1e-3 and (occ != occ2).mean() < 1e-3
    assert np.array_equal(occ, valid)  # occluded == hit for tmax-bounded rays
    same = valid & valid2
    rel = np.abs(t[same] - t2[same]) / t2[same]
    assert (rel > 1e-5).mean() < 1e-3 and rel.max() < 1e-2
    one = same & (prim == prim2)
    assert (prim[same] != prim2[same]).mean() < 1e-3
    duv = np.maximum(np.abs(u[one] - u2[one]), np.abs(v[one] - v2[one]))
    assert (duv > 1e-5).mean() < 1e-3 and duv.max() < 1e-2
    assert not valid[~valid].any() and np.isinf(t[~valid]).all() and (u[~valid] == 0).all()


def test_rays_leaving_a_rectangle_do_not_hit_it_again():
    """From hit points offset as the renderer offsets them (drpt.render.spawn), rays into
    either side: none hits the rectangle it leaves. Negative control: without the offset,
    some do (the test can see a self-hit)."""
    rng = np.random.default_rng(3)
    tris = rectangles(rng, 4) * 7.0 + [30.0, -5.0, 12.0]  # off the origin, not unit-sized
    accel = InlineList(make_scene(tris))
    R = 30000
    k = rng.integers(0, len(tris), R)
    w = rng.dirichlet([1, 1, 1], R)
    p = np.einsum("rk,rkc->rc", w, tris[k])
    o0 = p + rng.normal(size=(R, 3)) * 3
    O, D = rays(o0, p - o0)
    h = accel.intersect(O, D, Float(np.inf))
    pts = Array3f(*tris.astype(np.float32)[:, 0].T)
    e1 = Array3f(*(tris.astype(np.float32)[:, 1] - tris.astype(np.float32)[:, 0]).T)
    e2 = Array3f(*(tris.astype(np.float32)[:, 2] - tris.astype(np.float32)[:, 0]).T)
    i = dr.select(h.valid, h.prim, 0)
    pt, ng, err = triangle_point(dr.gather(Array3f, pts, i), dr.gather(Array3f, e1, i),
                                 dr.gather(Array3f, e2, i), h.u, h.v)
    d2 = Array3f(*rng.normal(size=(R, 3)).T)
    # grazing directions too: the plane's own directions, tilted by little
    graze = Bool(rng.random(R) < 0.3)
    d2 = dr.select(graze, dr.cross(ng, d2) + ng * Float(rng.normal(size=R) * 1e-3), d2)
    pair = i // 2
    for offset, expect_clean in ((True, True), (False, False)):
        o2 = origin(pt, ng, err, d2) if offset else pt
        h2 = accel.intersect(o2, d2, Float(np.inf))
        again = (h.valid & h2.valid & (h2.prim // 2 == pair)).numpy()
        assert h.valid.numpy().mean() > 0.8
        if expect_clean:
            assert not again.any(), f"{again.sum()} rays hit the rectangle they leave"
        else:
            assert again.any()


def test_trapezoid_far_from_the_origin_is_not_paired(monkeypatch):
    """The tolerance that decides "parallelogram" scales with the pair's own edges (plus the
    float32 rounding of its corners), not with its distance from the origin: a 0.02-wide
    trapezoid at 1000 whose fourth corner lies 5e-4 (2.5% of a side) off ``c + e1 + e2`` is
    two triangles, as it is at the origin; a true rectangle there (its corners rounded to
    float32) is still paired. Negative control: the old rule (tolerance relative to the
    largest coordinate) pairs the trapezoid."""
    quad = np.float64([[0, 0, 0], [0.02, 0, 0], [0.02, 0.02, 0], [0, 0.02, 0]])
    trap = quad.copy()
    trap[2, 0] += 5e-4
    at = [1000.0, 1000.0, 1000.0]

    def pairs(corners):
        return [q.first for q in parallelogram_pairs(np.stack([corners[list(f)] for f in FACES]))]

    assert pairs(trap) == [] and pairs(trap + at) == []
    assert pairs(quad) == [0] and pairs(quad + at) == [0]
    rng = np.random.default_rng(4)
    for _ in range(20):  # rotated rectangles far off, their corners rounded to float32
        m, _r = np.linalg.qr(rng.normal(size=(3, 3)))
        c = (quad * rng.uniform(0.5, 50)) @ m.T + rng.uniform(-2000, 2000, 3)
        assert pairs(c) == [0]
    monkeypatch.setattr(pg, "ROUNDING_TOLERANCE", 0.0)
    monkeypatch.setattr(pg, "_edge_scale", lambda e1, e2, extent: extent)
    assert pairs(trap + at) == [0]


def test_a_rectangle_in_a_plane_primitive_is_not_paired():
    """A rectangle lying in one of the scene's infinite planes (which the accelerators test
    before any triangle) stays two triangles, as beside a coplanar triangle: ties between the
    two are float rounding, and the watertight tests order them alike. Negative control: the
    plane moved off the rectangle by 1e-3, or no planes given, pairs it."""
    rect = np.stack([CORNERS[list(f)] for f in FACES]) * 3 + [5.0, 1.0, 2.0]
    floor = ([[0.0, 0.0, 2.0]], [4.0])  # 2 z = 4: the rectangle's plane z = 2
    assert parallelogram_pairs(rect, planes=floor) == []
    assert [q.first for q in parallelogram_pairs(rect, planes=([[0.0, 0.0, 2.0]], [4.002]))] == [0]
    assert [q.first for q in parallelogram_pairs(rect)] == [0]
    assert len(InlineList(make_scene(rect, planes=floor)).quads) == 0
    assert len(InlineList(make_scene(rect, planes=([[0.0, 0.0, 2.0]], [4.002]))).quads) == 1
    # the other triangles given apart (a list that is part of a scene): a vertex in the
    # pair's plane leaves it unpaired, one 1e-3 off does not
    standing = np.float64([[[5, 1, 2], [6, 1, 3], [5, 2, 3]]])
    assert parallelogram_pairs(rect, others=standing) == []
    assert [q.first for q in parallelogram_pairs(rect, others=standing + [0, 0, 1e-3])] == [0]
