"""Analytic tests of the pure ray/primitive functions in drpt.geometry."""

from __future__ import annotations

import numpy as np
from drjit.auto import Array3f, Float

from drpt.geometry import intersect_plane, intersect_sphere, intersect_triangle, intersect_triangle_watertight

INF = float("inf")


def v3(*rows):
    a = np.asarray(rows, np.float32).reshape(-1, 3)
    return Array3f(a[:, 0], a[:, 1], a[:, 2])


def test_triangle_known_hit_and_barycentrics():
    p0, p1, p2 = v3(0, 0, 0), v3(1, 0, 0), v3(0, 1, 0)
    o = v3([0.25, 0.5, 2.0], [0.25, 0.5, -3.0], [2.0, 2.0, 1.0], [0.1, 0.1, 1.0])
    d = v3([0, 0, -1], [0, 0, 2], [0, 0, -1], [1, 0, 0])  # last one parallel
    for res in (intersect_triangle(o, d, p0, p1 - p0, p2 - p0, Float(INF)),
                intersect_triangle_watertight(o, d, p0, p1, p2, Float(INF))):
        t, u, v, hit = (x.numpy() for x in res)
        assert hit.tolist() == [True, True, False, False]
        assert np.allclose(t[:2], [2.0, 1.5])
        assert np.allclose(u[:2], 0.25) and np.allclose(v[:2], 0.5)
        assert np.isinf(t[2:]).all() and not np.isnan(u).any() and not np.isnan(v).any()


def test_triangle_tmax_and_origin_on_surface():
    p0, p1, p2 = v3(0, 0, 0), v3(1, 0, 0), v3(0, 1, 0)
    o = v3([0.2, 0.2, 1.0], [0.2, 0.2, 0.0], [0.2, 0.2, 0.0])
    d = v3([0, 0, -1], [0, 0, 1], [0, 0, -1])
    t, u, v, hit = intersect_triangle_watertight(o, d, p0, p1, p2, Float([0.5, 10, 10]))
    assert not hit.numpy().any()  # beyond tmax; starting on the surface: no t == 0


def test_degenerate_triangle_no_nan():
    p0, p1, p2 = v3(0, 0, 0), v3(1, 1, 1), v3(2, 2, 2)  # collinear
    o = v3([0.5, 0.5, 3.0], [1, 1, 1], [0, 0, -1])
    d = v3([0, 0, -1], [1, 1, 1], [0, 0, 1])
    for res in (intersect_triangle(o, d, p0, p1 - p0, p2 - p0, Float(INF)),
                intersect_triangle_watertight(o, d, p0, p1, p2, Float(INF))):
        t, u, v, hit = (x.numpy() for x in res)
        assert not hit.any() and not np.isnan(t).any() and not np.isnan(u).any()


def test_sphere_outside_inside_tangent():
    c, r = v3(0, 0, 5), Float(1.0)
    o = v3([0, 0, 0], [0, 0, 5], [0, 0, 0], [1.0001, 0, 0], [0, 0, 0], [0, 0, 10])
    d = v3([0, 0, 1], [1, 0, 0], [0, 0, -1], [0, 0, 1], [0, 0, 2], [0, 0, 1])
    t, hit = (x.numpy() for x in intersect_sphere(o, d, c, r, Float(INF)))
    assert hit.tolist() == [True, True, False, False, True, False]
    assert np.allclose(t[[0, 1, 4]], [4.0, 1.0, 2.0])
    assert not np.isnan(t).any()


def test_sphere_far_away_precision():
    # small sphere very far away: the naive b^2 - ac loses everything in float32
    c, r = v3(0, 0, 1e4), Float(0.01)
    o = v3([0, 0.005, 0])
    d = v3([0, 0, 1])
    t, hit = intersect_sphere(o, d, c, r, Float(INF))
    expect = 1e4 - np.sqrt(0.01**2 - 0.005**2)
    assert hit.numpy()[0] and abs(t.numpy()[0] - expect) < 2e-3


def test_plane_hit_and_parallel():
    n, off = v3(0, 1, 0), Float(2.0)
    o = v3([0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 4, 0])
    d = v3([0, 1, 0], [1, 0, 0], [0, -1, 0], [0, -2, 0])
    t, hit = (x.numpy() for x in intersect_plane(o, d, n, off, Float(INF)))
    assert hit.tolist() == [True, False, False, True]
    assert np.allclose(t[[0, 3]], [2.0, 1.0]) and not np.isnan(t).any()
