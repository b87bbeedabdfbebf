"""The emitter density MIS weighs a BSDF- or phase-sampled hit with is next-event estimation's
density from the same point (:meth:`drpt.render.scene.DeviceScene.eval_emitter`'s ``ref``,
:meth:`drpt.render.integrators.volpath.VolPathIntegrator.emitted`).

A vertex's next ray starts at the vertex moved off its surface (:mod:`drpt.render.spawn`'s
offset, a bound on the hit point's rounding error), while next-event estimation sampled the
emitter from the vertex itself. Where the density depends on the point (an emissive triangle
sampled by its solid angle), the two techniques' weights then disagree for the same path.
The scene here makes the offset large against the distance to the light: a floor at
``z = 1000`` (offset about 2e-4, from the float32 coordinates' rounding) with a small light
0.01 above it, facing down. From points on the floor, next-event estimation's density for its
sample equals the density ``eval_emitter`` gives the hit of a ray that leaves the spawned
origin along the sampled direction, when seen from the vertex (relative 1e-5; the same
spherical triangle, computed from the same point); negative control: seen from the ray's
origin (no ``ref``, the density of a ray that started there), the densities differ by more
than 1% on most lanes. volpath's ``emitted`` passes the path's last scattering vertex: its MIS
weight against a known BSDF density is the power heuristic of next-event estimation's density
(negative control: the same state whose ``ref_p`` is the spawned origin gives other weights).
"""

from __future__ import annotations

import drjit as dr
import numpy as np
from drjit.auto import Array3f, Bool, Float, UInt32

from drpt.options import PathOptions, RenderOptions
from drpt.render.integrators.common import power_heuristic
from drpt.render.integrators.volpath import Flight, VolPathIntegrator, VolPathState
from drpt.render.scene import DeviceScene
from drpt.scene.model import Material, Medium, PerspectiveCamera, Scene, Triangles
from support.mis import floor_vertices

Z = 1000.0  # the floor's height: large coordinates, a large spawn offset
H = 0.01  # the light's height above the floor
N = 4096


def _model() -> Scene:
    floor = [[(-1, -1, Z), (1, -1, Z), (1, 1, Z)], [(-1, -1, Z), (1, 1, Z), (-1, 1, Z)]]
    # a small triangle facing down (clockwise seen from above: its normal is -z)
    light = [[(0, 0, Z + H), (0, 0.02, Z + H), (0.02, 0, Z + H)]]
    tris = Triangles(np.array(floor + light, float), np.array([0, 0, 1], np.int32))
    mats = [Material("floor"), Material("light", emission=(1, 1, 1))]
    cam = PerspectiveCamera((0, 0, Z + 5), (0, 0, Z), (0, 1, 0), 40)
    return Scene(path=None, camera=cam, materials=mats, triangles=tris, media=[Medium("fog")])


def _vertices(scene: DeviceScene):
    """Floor points 0.005-0.05 beside the light (rays straight down onto the floor), and a
    next-event sample of the light from each."""
    return floor_vertices(scene, N, Z)[2:]


def test_the_density_at_a_hit_is_seen_from_the_vertex():
    scene = DeviceScene(_model(), RenderOptions(width=4, height=4, spp=1, triangle_sampling="solid-angle"))
    assert scene.area_lights.spherical
    si, es, hit, ok = _vertices(scene)
    okn = np.array(ok)
    assert okn.mean() > 0.5
    want = np.array(es.pdf)[okn]
    _, seen = scene.eval_emitter(hit, es.wo, ok, radiance=False, ref=si.p)
    np.testing.assert_allclose(np.array(seen)[okn], want, rtol=1e-5)
    # negative control: seen from where the ray started (the vertex moved off the floor)
    _, moved = scene.eval_emitter(hit, es.wo, ok, radiance=False)
    off = np.abs(np.array(moved)[okn] / want - 1)
    assert np.mean(off > 0.01) > 0.5, np.median(off)


def test_volpath_weighs_a_hit_against_the_density_from_its_last_vertex():
    model = _model()
    opts = RenderOptions(width=4, height=4, spp=1, triangle_sampling="solid-angle")
    scene = DeviceScene(model, opts)
    integ = VolPathIntegrator(scene, PathOptions(max_depth=4), model)
    si, es, hit, ok = _vertices(scene)
    okn = np.array(ok)
    prev_pdf = Float(np.full(N, 0.3, np.float32))  # a BSDF density for the direction

    def weights(ref_p):
        s = VolPathState(o=scene.spawn(si, es.wo), d=es.wo, L=dr.zeros(Array3f, N), beta=Array3f(1.0, 1.0, 1.0),
                         eta=Float(1.0), depth=UInt32(1), prev_pdf=prev_pdf, prev_delta=Bool(False),
                         ref_p=ref_p, medium=UInt32(0), active=ok)
        fl = Flight(beta=Array3f(1.0, 1.0, 1.0), depth=UInt32(1), scatter=Bool(False), scatter_live=Bool(False),
                    surf=Bool(ok), p_med=Array3f(si.p), in_medium=Bool(False), g=Float(0.0))
        return np.array(integ.emitted(scene, s, hit, fl).x)[okn]  # (the light's radiance is 1)

    want = np.array(power_heuristic(prev_pdf, es.pdf))[okn]
    np.testing.assert_allclose(weights(si.p), want, rtol=1e-5)
    # negative control: a last vertex at the spawned origin weighs by another density
    moved = weights(scene.spawn(si, es.wo))
    assert np.mean(np.abs(moved / want - 1) > 1e-3) > 0.5
