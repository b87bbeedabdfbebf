"""The embree accelerator (drpt.accel.embree): hits against brute force (triangles,
spheres, planes, tmax, masks, symbolic and evaluated loops, inside a symbolic loop of
the caller), its place in --accel auto, and a clear error where Embree is missing."""

from __future__ import annotations

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array3f, Bool, Float, UInt32

from drpt.accel import build_accel, embree_lib, resolve_kind
from drpt.accel.embree import EmbreeAccel
from drpt.errors import DrptError
from support.accel import brute_hits, make_scene, mixed_scene_and_rays, rays, soup

INF = float("inf")
needs_embree = pytest.mark.skipif(embree_lib.reason() is not None,
                                  reason=f"{embree_lib.reason()}")


def _compare(h, g, tol=1e-5):
    """Embree's hits agree with brute force: the same rays hit, at the same ``t``;
    the prim agrees except at ties, where ``t`` still agrees. Returns the number of
    rays whose prim differs."""
    hv, gv = h.valid.numpy(), g.valid.numpy()
    ht, gt = h.t.numpy(), g.t.numpy()
    assert np.array_equal(hv, gv)
    assert np.allclose(ht[hv], gt[gv], rtol=tol, atol=0)
    assert np.all(np.isinf(ht[~hv]))
    diff = h.prim.numpy() != g.prim.numpy()
    assert np.allclose(ht[diff], gt[diff], rtol=tol, atol=0)
    return int(diff.sum())


@needs_embree
@pytest.mark.parametrize("sym", [True, False], ids=["symbolic", "evaluated"])
def test_embree_vs_brute(sym):
    sc, o, d, rng = mixed_scene_and_rays()
    R = len(o)
    O, D = rays(o, d)
    with dr.scoped_set_flag(dr.JitFlag.SymbolicLoops, sym):
        g = brute_hits(sc, o, d)
        e = build_accel(sc, "embree")
        h = e.intersect(O, D, Float(np.full(R, INF, np.float32)))
        assert _compare(h, g) <= R // 100
        # barycentrics of triangle hits: the same point on the same triangle
        F = len(sc.triangles)
        same = h.valid.numpy() & (h.prim.numpy() == g.prim.numpy()) & (g.prim.numpy() < F)
        assert np.allclose(h.u.numpy()[same], g.u.numpy()[same], atol=1e-4)
        assert np.allclose(h.v.numpy()[same], g.v.numpy()[same], atol=1e-4)
        sph = h.valid.numpy() & (h.prim.numpy() >= F)
        assert sph.any() and np.all(h.u.numpy()[sph] == 0)
        tm = np.float32(rng.random(R) * 6)
        occ = e.occluded(O, D, Float(tm)).numpy()
        gt = g.t.numpy()
        exp = g.valid.numpy() & (gt < tm)
        near = np.abs(gt - tm) < 1e-4 * np.maximum(1, tm)
        assert np.array_equal(occ[~near], exp[~near])
        assert occ.any() and not occ.all()


@needs_embree
def test_coherent_camera_rays_hit_what_incoherent_ones_hit():
    """``coherent`` (Embree's coherent traversal, for camera rays) changes no hit: for every
    lane mask (none, all, every other lane) the hits equal the incoherent query's, and the
    inactive lanes still report nothing (negative control: a query whose lanes are all
    inactive returns no hit, so a flag that took the place of the mask would fail)."""
    sc, o, d, _ = mixed_scene_and_rays()
    R = len(o)
    O, D = rays(o, d)
    e = build_accel(sc, "embree")
    tmax = Float(np.full(R, INF, np.float32))
    base = e.intersect(O, D, tmax)
    for coherent in (True, Bool(np.arange(R) % 2 == 0)):
        h = e.intersect(O, D, tmax, True, coherent)
        assert np.array_equal(h.valid.numpy(), base.valid.numpy())
        assert np.array_equal(h.prim.numpy(), base.prim.numpy())
        assert np.allclose(h.t.numpy()[base.valid.numpy()], base.t.numpy()[base.valid.numpy()], rtol=1e-6)
    assert base.valid.numpy().any()
    off = e.intersect(O, D, tmax, Bool(np.zeros(R, bool)), True)
    assert not off.valid.numpy().any()


@needs_embree
def test_coherent_shadow_rays_find_what_incoherent_ones_find():
    """``occluded``'s ``coherent`` (Embree's coherent traversal) changes no answer, for every
    lane mask; a query whose lanes are all inactive reports nothing (the negative control
    that the flag does not take the place of the mask)."""
    sc, o, d, rng = mixed_scene_and_rays()
    R = len(o)
    O, D = rays(o, d)
    e = build_accel(sc, "embree")
    tm = Float(np.float32(rng.random(R) * 6))
    base = e.occluded(O, D, tm).numpy()
    assert base.any() and not base.all()
    for coherent in (True, Bool(np.arange(R) % 2 == 0)):
        assert np.array_equal(e.occluded(O, D, tm, True, coherent).numpy(), base)
    assert not e.occluded(O, D, tm, Bool(np.zeros(R, bool)), True).numpy().any()


@needs_embree
def test_embree_tmax_and_mask():
    """``tmax`` cuts hits off and inactive lanes report nothing; planes beyond a
    nearer triangle do not win; a sphere-only scene maps ids past the triangles."""
    tri = np.float64([[[-1, -1, 0], [1, -1, 0], [0, 1, 0]]])
    sc = make_scene(tri, planes=([[0.0, 0.0, 1.0]], [-3.0]))  # plane z = -3
    e = EmbreeAccel(sc)
    o = np.float64([[0, 0, 2], [0, 0, 2], [5, 5, 2], [0, 0, 2]])
    d = np.float64([[0, 0, -1]] * 4)
    O, D = rays(o, d)
    h = e.intersect(O, D, Float([INF, 1.5, INF, INF]), Bool([True, True, True, False]))
    assert h.valid.numpy().tolist() == [True, False, True, False]
    assert np.allclose(h.t.numpy()[[0, 2]], [2.0, 5.0])
    assert h.prim.numpy().tolist()[:3] == [0, 0xFFFFFFFF, 1]  # the plane is id F + S + 0
    occ = e.occluded(O, D, Float([INF, 1.5, 4.0, INF]), Bool([True, True, True, False]))
    assert occ.numpy().tolist() == [True, False, False, False]
    sph = make_scene(np.zeros((0, 3, 3)), spheres=(np.float64([[0, 0, 0]]), np.float64([0.5])))
    hs = EmbreeAccel(sph).intersect(O, D, Float(INF))
    assert hs.prim.numpy().tolist() == [0, 0, 0xFFFFFFFF, 0] and np.allclose(hs.t.numpy()[0], 1.5)


@needs_embree
def test_embree_in_a_symbolic_loop():
    """Queried inside the caller's symbolic loop (as the megakernel does), a ray that
    hops from hit to hit counts the layers of a stack of parallel triangles."""
    layers = 7
    tris = np.stack([np.float64([[-1, -1, z], [1, -1, z], [0, 1, z]]) for z in range(layers)])
    e = EmbreeAccel(make_scene(tris))
    n = 64
    o = Array3f(dr.zeros(Float, n), dr.zeros(Float, n), Float(-1.0) + dr.zeros(Float, n))
    d = Array3f(0.0, 0.0, 1.0)

    def body(o, k, alive):
        h = e.intersect(o, d, Float(INF), alive)
        alive &= h.valid
        o = Array3f(o.x, o.y, dr.select(alive, o.z + h.t * 1.0001, o.z))
        return o, dr.select(alive, k + 1, k), alive

    _, k, _ = dr.while_loop((o, dr.zeros(UInt32, n), dr.full(Bool, True, n)),
                            lambda o, k, alive: alive, body)
    assert np.all(k.numpy() == layers)


@needs_embree
def test_auto_picks_embree_unless_a_bvh_rule_is_asked():
    rng = np.random.default_rng(3)
    big = make_scene(soup(rng, 200))
    assert resolve_kind(big) == "embree"
    assert isinstance(build_accel(big), EmbreeAccel)
    assert resolve_kind(big, bvh_rule=True) == "bvh"
    assert not isinstance(build_accel(big, method="sah"), EmbreeAccel)


def test_missing_embree_is_one_clear_error(monkeypatch):
    monkeypatch.setattr(embree_lib, "reason", lambda: "Embree 3 not found (apt-get install libembree3-3)")
    rng = np.random.default_rng(3)
    big = make_scene(soup(rng, 200))
    with pytest.raises(DrptError, match="libembree3-3"):
        build_accel(big, "embree")
    from drpt.accel import registry

    monkeypatch.setattr(registry, "embree_unavailable", embree_lib.reason)
    assert resolve_kind(big) == "bvh"


@needs_embree
def test_scene_outlives_its_accelerator_until_queries_ran():
    """A query traced but not yet evaluated keeps the Embree scene alive after its
    accelerator is collected; once evaluated, the scene is released."""
    import gc

    from drpt.accel import embree as emb

    def lazy_hit():
        tri = np.float64([[[-1, -1, 0], [1, -1, 0], [0, 1, 0]]] * 100)
        e = EmbreeAccel(make_scene(tri))
        return e.intersect(Array3f(0.0, 0.0, 2.0) + dr.zeros(Array3f, 16), Array3f(0.0, 0.0, -1.0),
                           Float(INF))

    h = lazy_hit()
    gc.collect()
    assert len(emb._retired) >= 1  # kept: the unevaluated query refers to it
    assert np.allclose(h.t.numpy(), 2.0)
    del h
    gc.collect()
    emb._reap()
    assert emb._retired == []


_SPHERE_XML = """<scene version="3.0.0">{flag}
  <sensor type="perspective"><float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>
  <shape type="obj"><string name="filename" value="{obj}"/><bsdf type="diffuse"/></shape>
</scene>"""


@needs_embree
def test_robust_mode_follows_the_file(tmp_path):
    """Embree's robust triangle test is on for drpt's own scenes and, in a Mitsuba XML, as its
    ``embree_use_robust_intersections`` says (Mitsuba's default: off). Rays from inside a closed
    uv sphere aimed at its vertices all hit it in robust mode; without it some slip between
    neighbouring triangles (the negative control that the flag reaches Embree)."""
    from pathlib import Path

    from drpt.scene import load_scene

    obj = Path(__file__).resolve().parents[1] / "data" / "xml" / "uvsphere.obj"
    verts = np.array([[float(x) for x in line.split()[1:4]] for line in obj.read_text().splitlines()
                      if line.startswith("v ")])
    # each vertex aimed at from 64 points near the center
    O = np.float64([0.1, -0.2, 0.05]) + np.random.default_rng(1).uniform(-1e-3, 1e-3, (len(verts) * 64, 3))
    D = verts.repeat(64, axis=0) - O
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    misses = {}
    for flag, robust in (("", False), ('<boolean name="embree_use_robust_intersections" value="true"/>', True),
                         ('<boolean name="embree_use_robust_intersections" value="false"/>', False)):
        path = tmp_path / f"sphere_{len(flag)}.xml"
        path.write_text(_SPHERE_XML.format(flag=flag, obj=obj))
        scene = load_scene(path)
        assert scene.settings.embree_robust is robust and scene.settings.not_read == ()
        e = EmbreeAccel(scene)
        assert e.robust is robust
        h = e.intersect(*rays(O, D), Float(INF))
        misses[robust] = int((~h.valid.numpy()).sum())
    assert misses[True] == 0 and misses[False] > 0, misses
    assert EmbreeAccel(make_scene(soup(np.random.default_rng(3), 200))).robust  # drpt's own: robust
