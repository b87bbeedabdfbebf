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
* the selection over every emitter (``BVHSelection``): the area slots by the BVH, sharing
  what ``mixed`` gives them in all, the point light and the sky with ``mixed``'s
  probabilities; pmf sums to 1; 200k draws against ``pmf`` (chi-square p > 1e-3), negative
  control: judged by ``mixed``'s probabilities (p < 1e-9); ``pdf_emitter`` of each
  next-event sample's ray is the sample's ``pdf`` (triangles, spheres, the sky);
* renders with ``--light-sampler bvh`` agree with ``power`` (block z-test, max |z| < 4.5)
  on a 50-light scene (megakernel, wavefront, ``ldsampler``) and on the bundled Cornell box
  (whose light is one quad: two triangles with the same bounds, so that the BVH picks as
  power does and the test checks its densities and MIS); negative control: MIS weights from a
  pmf 20x too small fail it (|z| > 6);
* the 50-light scene with a point light and a sky renders with ``bvh`` like ``mixed`` in the
  path, Whitted and volumetric path integrators (max |z| < 4.5); negative control: the sky's
  MIS probability 20x too small (|z| > 6).
"""

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array2f, Array3f, Bool, Float, UInt32
from scipy import stats

from drpt.render.lights.light_bvh import BVHSelection, LightBVH, leaf_slots, union_cones
from drpt.scene.model import Material, PerspectiveCamera, PointLight, Scene, Skybox, Spheres, Triangles


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


# ------------------------------------------------------------ the selection over every emitter
CAM = PerspectiveCamera((0, 0, 5), (0, 0, -1), (0, 1, 0), 40)
REFS_SEL = np.array([[4.0, 0.5, 2.0], [0.5, 0.3, 0.6], [11.0, 0.0, 1.5]])


def _scene(tmp_path, others=True):
    """Six triangle lights facing +z at z = 0 (x = 0, 1.5, ..., each its own power), two
    emissive spheres at x = 10 and 12, and (``others``) a point light and a sky."""
    tris = [[[1.5 * k, 0, 0], [1.5 * k + 1, 0, 0], [1.5 * k, 1, 0]] for k in range(6)]
    mats = [Material(f"e{k}", emission=(k + 1.0, 1.0, 0.5)) for k in range(6)]
    mats.append(Material("s", emission=(3.0, 3.0, 3.0)))
    spheres = Spheres(np.array([[10.0, 0, 0], [12.0, 0, 0]]), np.array([0.2, 0.5]), np.array([6, 6], np.int32))
    scene = Scene(path=None, camera=CAM, materials=mats, spheres=spheres,
                  triangles=Triangles(np.array(tris, float), np.arange(6, dtype=np.int32)))
    if others:
        from drpt.imageio import write_image

        img = np.ones((16, 32, 3), np.float32) * 0.2
        img[3:5, 20:23] = 40.0  # a sun
        write_image(tmp_path / "sky.exr", img)
        scene.lights += [PointLight((3.0, 2.0, 3.0), (4.0, 4.0, 4.0)), Skybox(tmp_path / "sky.exr")]
    return scene


def _device(scene, rule="bvh"):
    from drpt.options import RenderOptions
    from drpt.render.scene import DeviceScene

    return DeviceScene(scene, RenderOptions(light_sampler=rule, delta_lights="select"))  # (delta lights selected)


def _sel_pmf_table(sel, refs):
    n, P = sel.count, len(refs)
    idx = UInt32(np.tile(np.arange(n, dtype=np.uint32), P))
    return np.array(sel.pmf(idx, _v3(np.repeat(refs, n, axis=0)), True)).reshape(P, n)


def test_selection_covers_the_area_emitters_and_keeps_the_others_mixed(tmp_path):
    """The BVH's selection: area slots by the BVH (their total is mixed's), the point
    light and the sky with mixed's probabilities; everything sums to 1 at points every
    emitter faces."""
    scene = _scene(tmp_path)
    sel = _device(scene).emitter_selection
    assert type(sel).__name__ == "BVHSelection" and not sel.static
    assert [type(f).__name__ for f in sel.families] == ["AreaLights", "DeltaLights", "SkyEmitter"]
    assert sel.count == 8 + 1 + 1 and sel.groups == 3
    mixed = _device(scene, "mixed").emitter_selection.probabilities
    table = _sel_pmf_table(sel, REFS_SEL)
    np.testing.assert_allclose(table.sum(axis=1), 1.0, rtol=1e-5)
    np.testing.assert_allclose(table[:, 8:], np.tile(mixed[8:], (len(REFS_SEL), 1)), rtol=1e-6)
    np.testing.assert_allclose(table[:, :8].sum(axis=1), mixed[:8].sum(), rtol=1e-5)
    # the BVH's allocation differs from mixed's and from point to point (the nearest lights)
    assert np.abs(table[:, :8] - mixed[:8]).max() > 0.05
    assert np.argmax(table[0, :8]) != np.argmax(table[2, :8])


def _sel_histogram(sel, ref, n, seed):
    rng = np.random.default_rng(seed)
    k, pmf = sel.sample(Float(rng.random(n).astype(np.float32)), _v3(np.tile(ref, (n, 1))),
                        dr.full(Bool, True, n))
    return np.array(k), np.array(pmf)


@pytest.mark.parametrize("others", [True, False], ids=["every family", "area only"])
def test_selection_draws_what_it_reports(tmp_path, others):
    """Chi-square (p > 1e-3) of 200k draws at a point against ``pmf`` over every slot;
    the pmf a draw reports is ``pmf(index)``; negative control: judged by mixed's
    static probabilities the same draws fail (p < 1e-9)."""
    scene = _scene(tmp_path, others)
    sel = _device(scene).emitter_selection
    ref = REFS_SEL[0]
    p = _sel_pmf_table(sel, ref[None])[0]
    k, pmf = _sel_histogram(sel, ref, 200_000, seed=8)
    assert np.all(pmf > 0)
    counts = np.bincount(k, minlength=sel.count)
    assert _chi2(np.append(counts, 0), np.append(p, 0.0)) > 1e-3
    np.testing.assert_allclose(pmf, p[k], rtol=1e-5)
    mixed = _device(scene, "mixed").emitter_selection.probabilities
    assert _chi2(np.append(counts, 0), np.append(mixed, 0.0)) < 1e-9


def test_pdf_emitter_is_the_density_of_sample_emitter(tmp_path):
    """Every next-event sample whose ray reaches the emitter it was drawn on gets its own
    ``pdf`` back from ``pdf_emitter`` (the BVH's pmf at the ray's origin, relative 1e-3),
    on triangles, spheres and the sky; the point light's pdf is its probability."""
    from types import SimpleNamespace

    ds = _device(_scene(tmp_path))
    sel, n = ds.emitter_selection, 20_000
    rng = np.random.default_rng(9)
    u = rng.random((3, n)).astype(np.float32)
    ref = REFS_SEL[0]
    ones = dr.full(Bool, True, n)
    refs = _v3(np.tile(ref, (n, 1)))
    es = ds.sample_emitter(SimpleNamespace(p=refs), Float(u[0]), Array2f(Float(u[1]), Float(u[2])), ones)
    k, _ = sel.sample(Float(u[0]), refs, ones)
    k = np.array(k)
    si = ds.intersect(refs, es.wo, ones)
    pdf = np.array(ds.pdf_emitter(si, es.wo, ones))
    got, valid = np.array(es.pdf), np.array(es.valid)
    prim = ds.area_lights._ids[np.minimum(k, 7)]
    reached = np.where(k < 8, np.array(si.valid) & (np.array(si.prim) == prim), ~np.array(si.valid))
    for name, lo, hi in (("triangles", 0, 6), ("spheres", 6, 8), ("sky", 9, 10)):
        both = (k >= lo) & (k < hi) & valid & reached
        assert both.sum() > 100, name
        np.testing.assert_allclose(pdf[both], got[both], rtol=1e-3, err_msg=name)
    point = (k == 8) & valid
    assert point.sum() > 100
    np.testing.assert_allclose(got[point], sel.pmf(UInt32(8), _v3(ref), True).numpy()[0], rtol=1e-6)


def test_bvh_without_area_emitters_is_mixed(tmp_path):
    scene = _scene(tmp_path)
    scene.materials = [Material(m.name, emission=(0.0, 0.0, 0.0)) for m in scene.materials]
    sel = _device(scene).emitter_selection
    assert sel.static and sel.rule == "mixed" and sel.count == 2


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
    real = BVHSelection.pmf
    monkeypatch.setattr(BVHSelection, "pmf", lambda self, *a: real(self, *a) * 0.05)
    assert _max_z(many_lights, 128) > 6


@pytest.mark.slow
@pytest.mark.parametrize("integrator,control", [("path", False), ("whitted", False), ("volpath", False),
                                               ("path", True)], ids=["path", "whitted", "volpath", "control"])
def test_every_family_render_agrees_with_mixed(many_lights, tmp_path, monkeypatch, integrator, control):
    """The 50-light scene with a point light and a sky (with a sun) added: ``bvh``
    (the area lights by the BVH, the point light and the sky by ``mixed``'s
    probabilities) against ``mixed`` (block z-test, max |z| < 4.5), in the path, Whitted
    and volumetric path integrators. Negative control: the probability of every slot but
    the area lights' 20x too small in MIS, so BSDF-sampled sky hits weigh too much (|z| > 6)."""
    from drpt.imageio import write_image
    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene
    from drpt.testing import block_z

    img = np.ones((16, 32, 3), np.float32) * 0.5
    img[3:5, 20:23] = 200.0  # a sun
    write_image(tmp_path / "sky.exr", img)
    scene = load_scene(many_lights)
    scene.lights += [PointLight((1.0, 3.0, 2.0), (30.0, 30.0, 30.0)), Skybox(tmp_path / "sky.exr")]
    if control:
        real = BVHSelection.pmf

        def wrong(self, index, ref, active=True):
            p = real(self, index, ref, active)
            return dr.select(index >= self.area_count, p * 0.05, p)
        monkeypatch.setattr(BVHSelection, "pmf", wrong)

    def render(rule, seed):
        opts = RenderOptions(width=64, height=48, spp=128, seed=seed, light_sampler=rule, progress=False,
                             integrator=integrator)
        r = Renderer(scene, opts)
        assert type(r.scene.emitter_selection).__name__ == ("BVHSelection" if rule == "bvh" else "LightSelection")
        return r.render()

    a, b = render("bvh", 1), render("mixed", 2)
    assert np.all(np.isfinite(a.image)) and a.nonfinite == 0
    z = float(np.abs(block_z(a.image, a.variance, b.image, b.variance)).max())
    assert (z > 6) if control else (z < 4.5)
