"""The one light selection over every emitter (drpt/render/lights/selection.py) and the
scene's emitter query pair, ``DeviceScene.sample_emitter`` / ``pdf_emitter``.

* The selection draws each slot with the probability it reports: chi-square of 200,000
  draws over the slots of a scene with every family (emissive triangles of two shapes, two
  spheres, a point, a spot and a directional light, a sky), p > 1e-3, for ``power``,
  ``uniform`` and ``mixed``; ``pmf`` returns the same numbers; ``uniform`` gives each
  emitter ``1/N`` exactly, ``power`` each slot its share of :meth:`Emitter.power`, and
  ``mixed`` the mean of the two. Negative control:
  uniform's draws judged by power's probabilities fail (p < 1e-9).
* ``pdf_emitter`` is the density of ``sample_emitter``, family by family: in the same
  scene, every sample whose ray reaches the emitter it was drawn on (the primitive, or the
  sky by escaping) gets back its own ``pdf`` from ``pdf_emitter`` (relative 1e-3; delta
  lights: ``pdf`` is the slot's probability and ``delta`` is set); and the
  sampled directions pass Mitsuba's spherical chi-square test against ``pdf_emitter`` of
  the traced ray in a scene of triangles and spheres that do not hide each other, and in a
  scene with only a sky. Negative control: the same test with the density of the other
  selection rule fails.
* A spatially varying selection (``static = False``: the scene multiplies the pmf in at run
  time instead of binding it into the families' tables) renders the image of the static one.
"""

from types import SimpleNamespace

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array2f, Array3f, Bool, Float, UInt32
from scipy import stats

from drpt.options import RenderOptions
from drpt.render.lights.selection import LightSelection
from drpt.render.scene import DeviceScene
from drpt.scene.model import (
    DirectionalLight,
    Material,
    PerspectiveCamera,
    PointLight,
    Scene,
    Skybox,
    Spheres,
    SpotLight,
    Triangles,
)
from drpt.testing import mitsuba, spherical_chi2, to_drpt, to_mitsuba_float, to_mitsuba_vec3

CAM = PerspectiveCamera((0, 0, 5), (0, 0, -1), (0, 1, 0), 40)
REF = (0.0, 0.0, 0.0)  # the reference point every emitter faces


def _facing_triangle(center, normal, size):
    """A triangle around ``center`` whose front (winding) normal is ``normal``."""
    n = np.asarray(normal, float)
    a = np.cross(n, [0.3, 0.5, 0.8])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    c = np.asarray(center, float)
    return [c - size * a, c + size * a - size * b, c + size * b]  # (p1-p0) x (p2-p0) along n


def emitter_scene(tmp_path=None, delta=True, sky=True, spheres=True, size=1.0):
    """Emitters around the origin, each facing it and none hiding another: shape 0 (two
    triangles above, radiance 1), shape 1 (a triangle to the side, radiance 5), two
    spheres (radiance 3 and 0.5), a point, a spot and a directional light, and a sky."""
    tris = [_facing_triangle((0.5, 0.4, 2.0), (0, 0, -1), 0.4 * size),
            _facing_triangle((-0.9, -0.8, 2.5), (0, 0, -1), 0.3 * size),
            _facing_triangle((-3.0, 0.5, 0.2), (1, 0, 0), 0.5 * size)]
    materials = [Material("a", emission=(1, 1, 1)), Material("b", emission=(5, 4, 3)),
                 Material("c", emission=(3, 3, 3)), Material("d", emission=(0.5, 0.2, 0.1))]
    scene = Scene(path=None, camera=CAM, materials=materials,
                  triangles=Triangles(np.array(tris, float), np.array([0, 0, 1], np.int32),
                                      shape=np.array([0, 0, 1])))
    if spheres:
        scene.spheres = Spheres(np.array([[0.3, 0.2, -3.0], [3.0, -1.0, 0.5]]), np.array([0.4, 0.8]) * size,
                                np.array([2, 3], np.int32))
    if delta:
        scene.lights += [PointLight((1.0, 2.0, 1.0), (4.0, 4.0, 4.0)),
                         SpotLight((0.0, -2.0, 0.0), (0.0, 1.0, 0.0), (8.0, 6.0, 4.0)),
                         DirectionalLight((0.3, -1.0, 0.2), (0.5, 0.5, 0.5))]
    if sky:
        from drpt.imageio import write_image

        img = np.ones((16, 32, 3), np.float32) * 0.2
        img[3:5, 20:23] = 40.0  # a sun
        write_image(tmp_path / "sky.exr", img)
        scene.lights.append(Skybox(tmp_path / "sky.exr"))
    return scene


def device(scene, rule="power"):
    return DeviceScene(scene, RenderOptions(light_sampler=rule, delta_lights="select"))


def _draws(ds, n=200_000, seed=1):
    rng = np.random.default_rng(seed)
    u = Float(rng.random(n).astype(np.float32))
    k, pmf = ds.emitter_selection.sample(u, None, dr.full(Bool, True, n))
    return np.asarray(k.numpy()), np.asarray(pmf.numpy())


@pytest.mark.parametrize("rule", ["power", "uniform", "mixed"])
def test_selection_draws_what_it_reports(tmp_path, rule):
    ds = device(emitter_scene(tmp_path), rule)
    sel = ds.emitter_selection
    assert [type(f).__name__ for f in sel.families] == ["AreaLights", "DeltaLights", "SkyEmitter"]
    assert sel.count == 3 + 2 + 3 + 1 and sel.offsets == [0, 5, 8]
    p = sel.probabilities
    assert np.all(p > 0) and abs(p.sum() - 1.0) < 1e-12
    k, pmf = _draws(ds)
    counts = np.bincount(k, minlength=sel.count)
    _, pvalue = stats.chisquare(counts, p * counts.sum())
    assert pvalue > 1e-3, (pvalue, counts, p)
    np.testing.assert_allclose(pmf, p[k], rtol=1e-6)
    np.testing.assert_allclose(sel.pmf(UInt32(np.arange(sel.count, dtype=np.uint32))).numpy(), p, rtol=1e-6)
    if rule == "uniform":  # 7 emitters: shape 0 (split by area), shape 1, 2 spheres, 3 delta, sky
        area = ds.area_lights._area[ds.area_lights._ids]
        expect = np.array([area[0] / (area[0] + area[1]), area[1] / (area[0] + area[1])] + [1.0] * 7) / 8
        np.testing.assert_allclose(p, expect, rtol=1e-12)
    elif rule == "power":
        power = np.concatenate([f.power() for f in sel.families])
        np.testing.assert_allclose(p, power / power.sum(), rtol=1e-12)
    else:  # the mean of the other two
        scene = emitter_scene(tmp_path)
        halves = [device(scene, r).emitter_selection.probabilities for r in ("power", "uniform")]
        np.testing.assert_allclose(p, 0.5 * halves[0] + 0.5 * halves[1], rtol=1e-12)


def test_uniform_draws_fail_against_powers_probabilities(tmp_path):
    """Negative control of the histogram test."""
    scene = emitter_scene(tmp_path)
    k, _ = _draws(device(scene, "uniform"))
    p = device(scene, "power").emitter_selection.probabilities
    counts = np.bincount(k, minlength=len(p))
    assert stats.chisquare(counts, p * counts.sum())[1] < 1e-9


def _sample(ds, n, seed=1):
    rng = np.random.default_rng(seed)
    u = rng.random((3, n)).astype(np.float32)
    ref = SimpleNamespace(p=dr.full(Array3f, REF, n))
    es = ds.sample_emitter(ref, Float(u[0]), to_drpt(u[1:], Array2f), dr.full(Bool, True, n))
    k, _ = ds.emitter_selection.sample(Float(u[0]), None, dr.full(Bool, True, n))
    return es, k.numpy()


def test_pdf_emitter_is_the_density_of_sample_emitter_per_family(tmp_path):
    ds = device(emitter_scene(tmp_path))
    sel, n = ds.emitter_selection, 20_000
    es, k = _sample(ds, n)
    ones = dr.full(Bool, True, n)
    si = ds.intersect(dr.full(Array3f, REF, n), es.wo, ones)
    pdf = ds.pdf_emitter(si, es.wo, ones).numpy()
    got, valid, delta = es.pdf.numpy(), es.valid.numpy(), np.asarray(Bool(es.delta).numpy(), bool)
    area_end = sel.offsets[1]
    lights = ds.area_lights
    prim = lights._ids[np.minimum(k, area_end - 1)]
    reached = np.where(k < area_end, si.valid.numpy() & (si.prim.numpy() == prim), ~si.valid.numpy())
    for name, lo, hi in (("area", 0, 5), ("delta", 5, 8), ("sky", 8, 9)):
        mine = (k >= lo) & (k < hi) & valid
        assert mine.sum() > 200, name
        if name == "delta":
            assert delta[mine].all()  # (pdf_emitter there: whatever the ray reached behind it)
            np.testing.assert_allclose(got[mine], sel.probabilities[k[mine]], rtol=1e-6)
            continue
        assert not delta[mine].any()
        both = mine & reached
        assert both.sum() > 0.9 * mine.sum(), name  # (the emitters do not hide each other)
        np.testing.assert_allclose(pdf[both], got[both], rtol=1e-3, err_msg=name)
    # the spheres' lanes by the cone they subtend, the triangles' by area: both present
    assert (k[(k < area_end) & valid] >= 3).any() and (k[(k < area_end) & valid] < 3).any()


def _chi2(ds_sample, ds_pdf, **kw):
    """Mitsuba's spherical chi-square of sample_emitter's directions (3-D samples: the
    selection, then the point) from the origin against pdf_emitter of the traced ray."""
    mitsuba()

    def sample_func(u):
        a = np.array(u, np.float32)
        n = a.shape[1]
        ref = SimpleNamespace(p=dr.full(Array3f, REF, n))
        es = ds_sample.sample_emitter(ref, Float(a[0]), Array2f(Float(a[1]), Float(a[2])), dr.full(Bool, True, n))
        return to_mitsuba_vec3(es.wo)

    def pdf_func(w):
        d = to_drpt(w, Array3f)
        n = dr.width(d)
        ones = dr.full(Bool, True, n)
        si = ds_pdf.intersect(dr.full(Array3f, REF, n), d, ones)
        return to_mitsuba_float(ds_pdf.pdf_emitter(si, d, ones))

    # the densities have sharp edges (the emitters' outlines), which the integration of the pdf
    # over a bin resolves to about 1/ires of the bin: 32 points per bin side, and 100,000
    # samples (with 400,000 that error alone fails the test in the edges' bins)
    return spherical_chi2(sample_func, pdf_func, sample_dim=3, sample_count=100_000, res=61, ires=32, **kw)


@pytest.mark.mitsuba
@pytest.mark.parametrize("what", ["area", "sky"])
def test_sampled_directions_follow_pdf_emitter(tmp_path, what):
    """Area emitters (triangles and spheres) and the sky alone: the directions
    sample_emitter draws have pdf_emitter's density (each family's density on its own,
    as next-event estimation sees it)."""
    scene = emitter_scene(tmp_path, delta=False, sky=what == "sky", size=2.0)
    if what == "sky":  # the sky alone (no primitive in the way)
        scene.materials, scene.triangles, scene.spheres = [], type(scene.triangles).empty(), \
            type(scene.spheres).empty()
    ds = device(scene)
    assert [type(f).__name__ for f in ds.emitter_selection.families] == \
        (["AreaLights"] if what == "area" else ["SkyEmitter"])
    ok, msg = _chi2(ds, ds)
    assert ok, msg


@pytest.mark.mitsuba
def test_chi2_rejects_the_other_rules_density(tmp_path):
    """Negative control: power's directions against uniform's densities."""
    scene = emitter_scene(tmp_path, delta=False, sky=False, size=2.0)
    ok, _ = _chi2(device(scene, "power"), device(scene, "uniform"))
    assert not ok


class _Spatial(LightSelection):
    """The static selection behind the interface of a spatially varying one: the scene
    binds nothing and multiplies pmf(index, ref) in at run time."""

    static = False


@pytest.mark.parametrize("integrator", ["path", "whitted"])
def test_spatial_selection_interface_renders_the_static_image(tmp_path, integrator):
    from dataclasses import replace

    from drpt.render.renderer import Renderer

    scene = emitter_scene(tmp_path)
    opts = RenderOptions(width=16, height=16, spp=4, seed=2, progress=False, integrator=integrator)
    a = Renderer(scene, opts)
    ref = a.render().image
    b = Renderer(scene, replace(opts))
    sel = b.scene.emitter_selection
    b.scene.set_light_selection(_Spatial(sel.families, sel.rule))
    img = b.render().image
    assert np.abs(ref).max() > 0
    np.testing.assert_allclose(img, ref, rtol=1e-4, atol=1e-6)
