"""The light BVH (drpt/render/lights/light_bvh.py, ``--light-sampler bvh``).

* the host build: every emitter in its own leaf slot, cones that hold their children's;
* ``pmf`` sums to 1 over the emitters at random reference points (with and without a
  normal) where no subtree is a dead end; in general to 1 minus the probability that
  sampling fails (a node whose children both have no importance);
* sampling frequencies against ``pmf`` (chi-square over the emitters and the failure bin,
  fixed seed, p > 1e-3), and the ``pmf`` that ``sample`` returns is ``pmf(index)``;
  negative controls: the same histogram judged by the power distribution, and by the
  BVH's pmf at a point 0.5 away, fails (p < 1e-9);
* an emitter behind every one-sided light is never chosen (``pmf`` 0);
* ``AreaLights``: the densities ``sample`` reports are those ``pdf_area``/``pdf_sphere``
  give for the same point and reference;
* renders with ``--light-sampler bvh`` agree with ``power`` (block z-test, max |z| < 4.5)
  on a 50-light scene (megakernel, wavefront, ``ldsampler``) and on the bundled Cornell box
  (whose light is one quad: two triangles with the same bounds, so that the BVH picks as
  power does and the test checks its densities and MIS); negative control: MIS weights from a
  pmf 20x too small fail it (|z| > 6).
"""

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array2f, Array3f, Bool, Float, UInt32
from scipy import stats

from drpt.render.lights.area import AreaLights
from drpt.render.lights.light_bvh import LightBVH, leaf_slots, union_cones
from drpt.render.surface import SurfaceData
from drpt.scene.model import Material, PerspectiveCamera, Scene, Spheres, Triangles


def _v3(a: np.ndarray) -> Array3f:
    a = np.atleast_2d(np.asarray(a, np.float32))
    return Array3f(*(Float(np.ascontiguousarray(a[:, i])) for i in range(3)))


def random_emitters(m: int, seed: int, cones=(1.0, 0.9, 0.3, -1.0)):
    """``m`` boxes in [-5, 5]^3 with random normal cones (from ``cones``) and powers over
    two decades."""
    rng = np.random.default_rng(seed)
    c = rng.uniform(-5, 5, (m, 3))
    h = rng.uniform(0.01, 0.4, (m, 3))
    w = rng.normal(size=(m, 3))
    w /= np.linalg.norm(w, axis=1)[:, None]
    cos_o = rng.choice(cones, m)
    phi = np.exp(rng.uniform(0.0, np.log(100.0), m))
    return c - h, c + h, w, cos_o, np.zeros(m), phi


def pmf_table(bvh: LightBVH, refs: np.ndarray, normals: np.ndarray | None = None) -> np.ndarray:
    """``pmf(k)`` of every emitter at each reference point: ``(len(refs), m)``."""
    m, P = bvh.count, len(refs)
    idx = UInt32(np.tile(np.arange(m, dtype=np.uint32), P))
    n = None if normals is None else _v3(np.repeat(normals, m, axis=0))
    return np.array(bvh.pmf(idx, _v3(np.repeat(refs, m, axis=0)), n)).reshape(P, m)


# ------------------------------------------------------------ the build
@pytest.mark.parametrize("m", [1, 2, 3, 5, 8, 37, 64, 1000])
def test_every_emitter_has_its_own_leaf(m):
    rng = np.random.default_rng(m)
    depth, slot = leaf_slots(rng.normal(size=(m, 3)))
    assert depth == (0 if m == 1 else int(np.ceil(np.log2(m))))
    assert len(np.unique(slot)) == m and slot.min() >= 0 and slot.max() < 2 ** depth


def test_union_cone_holds_both_cones():
    rng = np.random.default_rng(0)
    n = 2000
    wa, wb = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    wa /= np.linalg.norm(wa, axis=1)[:, None]
    wb /= np.linalg.norm(wb, axis=1)[:, None]
    ca, cb = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)
    ca[:500], cb[500:1000] = 1.0, 1.0  # single directions
    w, c = union_cones(wa, ca, wb, cb)
    assert np.allclose(np.linalg.norm(w, axis=1), 1.0)
    t = np.arccos(np.clip(c, -1, 1))
    for wx, cx in ((wa, ca), (wb, cb)):
        reach = np.arccos(np.clip(np.einsum("ij,ij->i", w, wx), -1, 1)) + np.arccos(np.clip(cx, -1, 1))
        assert np.all((reach <= t + 1e-6) | (c <= -1.0))
    # and it is not the whole sphere when both are narrow and close
    w, c = union_cones(np.array([[0, 0, 1.0]]), np.array([0.99]), np.array([[0, 0.1, 1.0]]) / np.hypot(0.1, 1),
                       np.array([0.99]))
    assert c[0] > 0.9


# ------------------------------------------------------------ pmf and sampling
@pytest.mark.parametrize("m,with_normal", [(45, False), (45, True), (700, False)])
def test_pmf_sums_to_one(m, with_normal):
    """With emitters that shine in every direction (spheres: cos_o = -1) no node is a dead
    end, so the pmf over the emitters sums to 1 at any reference point."""
    bvh = LightBVH(*random_emitters(m, seed=1, cones=(-1.0,)))
    rng = np.random.default_rng(2)
    refs = rng.uniform(-7, 7, (64, 3))
    normals = rng.normal(size=(64, 3)) if with_normal else None
    if with_normal:
        normals /= np.linalg.norm(normals, axis=1)[:, None]
    s = pmf_table(bvh, refs, normals).sum(axis=1)
    np.testing.assert_allclose(s, 1.0, rtol=2e-5)


def _histogram(bvh, ref, n, seed, normal=None):
    rng = np.random.default_rng(seed)
    k, pmf = bvh.sample(Float(rng.random(n).astype(np.float32)), _v3(ref),
                        None if normal is None else _v3(normal))
    k, pmf = np.array(k), np.array(pmf)
    failed = pmf == 0
    counts = np.append(np.bincount(k[~failed], minlength=bvh.count), failed.sum())
    return counts, k, pmf


def _chi2(counts, p):
    keep = p * counts.sum() > 5  # pool the bins too rare for the chi-square approximation
    obs = np.append(counts[keep], counts[~keep].sum())
    exp = np.append(p[keep], p[~keep].sum()) * counts.sum()
    if exp[-1] == 0:
        assert obs[-1] == 0
        obs, exp = obs[:-1], exp[:-1]
    return stats.chisquare(obs, exp * obs.sum() / exp.sum()).pvalue


REFS = [((0.5, 0.2, 0.1), None), ((6.0, -2.0, 1.0), None), ((-1.0, 3.0, -4.0), (0.0, 1.0, 0.0))]


@pytest.mark.parametrize("ref,normal", REFS)
def test_sampling_frequencies_match_the_pmf(ref, normal):
    bvh = LightBVH(*random_emitters(37, seed=3))
    pm = pmf_table(bvh, np.array([ref]), None if normal is None else np.array([normal]))[0]
    assert pm.sum() <= 1 + 1e-5
    p = np.append(pm, max(0.0, 1.0 - pm.sum()))  # the last bin: sampling failed
    counts, k, pmf = _histogram(bvh, ref, 200_000, seed=4, normal=normal)
    assert _chi2(counts, p) > 1e-3
    ok = pmf > 0
    np.testing.assert_allclose(pmf[ok], pm[k[ok]], rtol=1e-5)


def test_sampling_judged_by_another_pmf_fails():
    """Negative controls: the histogram of one point's samples fails against the
    power distribution and against the BVH's pmf at a point 0.5 away."""
    emitters = random_emitters(37, seed=3)
    bvh = LightBVH(*emitters)
    ref = np.array(REFS[0][0])
    counts, _, _ = _histogram(bvh, ref, 200_000, seed=4)
    power = np.append(emitters[5] / emitters[5].sum(), 0.0)
    assert _chi2(counts, power) < 1e-9
    pm = pmf_table(bvh, np.array([ref + [0.5, 0.0, 0.0]]))[0]
    assert _chi2(counts, np.append(pm, max(0.0, 1.0 - pm.sum()))) < 1e-9


def test_lights_facing_away_are_never_chosen():
    """One-sided lights on the plane y = 0 facing +y: from below, no importance anywhere."""
    m = 20
    rng = np.random.default_rng(5)
    c = np.column_stack([rng.uniform(-3, 3, m), np.zeros(m), rng.uniform(-3, 3, m)])
    h = np.array([0.2, 0.0, 0.2])
    bvh = LightBVH(c - h, c + h, np.tile([0.0, 1.0, 0.0], (m, 1)), np.ones(m), np.zeros(m), np.ones(m))
    below = np.array([[0.0, -1.0, 0.0], [2.0, -3.0, 1.0]])  # (near the plane the bounds allow any)
    assert np.all(pmf_table(bvh, below) == 0.0)
    _, _, pmf = _histogram(bvh, below[0], 1000, seed=6)
    assert np.all(pmf == 0.0)
    np.testing.assert_allclose(pmf_table(bvh, np.array([[0.0, 1.0, 0.0]])).sum(), 1.0, rtol=1e-5)


# ------------------------------------------------------------ AreaLights with the BVH
CAM = PerspectiveCamera((0, 0, 5), (0, 0, -1), (0, 1, 0), 40)


def _area_lights():
    """Six triangle lights facing +z at z = 0 (x = 0, 1.5, ..., each its own power) and
    two emissive spheres at x = 10 and 12."""
    tris = [[[1.5 * k, 0, 0], [1.5 * k + 1, 0, 0], [1.5 * k, 1, 0]] for k in range(6)]
    mats = [Material(f"e{k}", emission=(k + 1.0, 1.0, 0.5)) for k in range(6)]
    mats.append(Material("s", emission=(3.0, 3.0, 3.0)))
    spheres = Spheres(np.array([[10.0, 0, 0], [12.0, 0, 0]]), np.array([0.2, 0.5]), np.array([6, 6], np.int32))
    scene = Scene(path=None, camera=CAM, materials=mats, spheres=spheres,
                  triangles=Triangles(np.array(tris, float), np.arange(6, dtype=np.int32)))
    return AreaLights(scene, SurfaceData(scene), sampler="bvh")


def test_area_lights_report_the_densities_they_evaluate():
    lights = _area_lights()
    assert lights.bvh is not None and lights.count == 8
    n = 50_000
    rng = np.random.default_rng(7)
    ref_np = np.array([4.0, 0.5, 2.0])
    ref = _v3(ref_np)
    ls = lights.sample(Float(rng.random(n).astype(np.float32)),
                       Array2f(rng.random((2, n)).astype(np.float32)), dr.full(Bool, True, n), ref=ref)
    p = np.array(ls.p).T
    prim = np.where(p[:, 0] < 9.0, np.floor(p[:, 0] / 1.5 + 1e-6), np.where(p[:, 0] < 11.0, 6, 7)).astype(np.uint32)
    refs = _v3(np.tile(ref_np, (n, 1)))
    prob = lights.bvh_pmf(UInt32(prim), refs, dr.full(Bool, True, n))
    tri = prim < 6
    pdf_t = np.array(lights.pdf_area(UInt32(prim), dr.full(Bool, True, n), prob))
    np.testing.assert_allclose(np.array(ls.pdf_area)[tri], pdf_t[tri], rtol=1e-5)
    np.testing.assert_allclose(pdf_t[tri], (2.0 * np.array(prob))[tri], rtol=1e-5)  # triangle area 0.5
    d = p - ref_np
    dist = np.linalg.norm(d, axis=1)
    is_sph, pdf_s = lights.pdf_sphere(UInt32(prim), _v3(p), refs, _v3(d / dist[:, None]),
                                      Float(dist.astype(np.float32)), dr.full(Bool, True, n))
    assert np.array_equal(np.array(is_sph), ~tri)
    np.testing.assert_allclose(np.array(ls.pdf_area)[~tri], np.array(pdf_s)[~tri], rtol=1e-4)
    assert np.array(ls.solid_angle)[~tri].all()
    # every light was chosen, and without a reference point the choice is by power
    assert set(np.unique(prim)) == set(range(8))
    ls0 = lights.sample(Float(0.5), Array2f(0.5, 0.5), Bool(True))
    assert float(ls0.pdf_area[0]) > 0


# ------------------------------------------------------------ renders: bvh against power
def _render(path, light_sampler, spp, seed, size=(64, 48), **kw):
    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    opts = RenderOptions(width=size[0], height=size[1], spp=spp, seed=seed, light_sampler=light_sampler,
                         progress=False, **kw)
    return Renderer(load_scene(path), opts).render()


def _max_z(path, spp, bvh_opts=None, **kw):
    from drpt.testing import block_z

    a = _render(path, "bvh", spp, seed=1, **kw, **(bvh_opts or {}))
    b = _render(path, "power", spp, seed=2, **kw)
    assert np.all(np.isfinite(a.image)) and a.nonfinite == 0
    return float(np.abs(block_z(a.image, a.variance, b.image, b.variance)).max())


@pytest.fixture(scope="module")
def many_lights(tmp_path_factory):
    from drpt.tools.scenegen import many_lights

    out = tmp_path_factory.mktemp("many_lights")
    many_lights.main(out, 50)
    return out / "many_lights.txt"


@pytest.mark.slow
@pytest.mark.parametrize("bvh_opts", [{}, {"mode": "wavefront"}, {"sampler": "ldsampler"}],
                         ids=["megakernel", "wavefront", "ldsampler"])
def test_many_lights_render_agrees_with_power(many_lights, bvh_opts):
    """The light BVH in the megakernel, the wavefront integrator and with the
    low-discrepancy sampler (whose light choice then keeps its own dimension) against
    power selection in the megakernel."""
    assert _max_z(many_lights, 128, bvh_opts) < 4.5


@pytest.mark.slow
def test_cornell_box_render_agrees_with_power(cornell):
    assert _max_z(cornell, 128, bsdf="auto") < 4.5


@pytest.mark.slow
def test_wrong_mis_pmf_fails_the_render_test(many_lights, monkeypatch):
    """Negative control: BSDF-sampled hits weighted with a pmf 20x too small."""
    real = AreaLights.bvh_pmf
    monkeypatch.setattr(AreaLights, "bvh_pmf", lambda self, *a: real(self, *a) * 0.05)
    assert _max_z(many_lights, 128) > 6
