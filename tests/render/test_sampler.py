"""The low-discrepancy sampler (drpt.render.sampler): its values, its stratification, and
renders with it.

* Sobol's second dimension from the superset-sum formula equals the one from its
  generator matrix (``v_1 = 2^31``, ``v_{k+1} = v_k ^ (v_k >> 1)``).
* Uniform: 1-D (64 bins) and 2-D (16x16 cells) histograms of the values of a dimension
  over 16384 pixels (one sample each, so independent scrambles) pass a chi-square test at
  p > 1e-4 (a fixed seed; the false-failure rate of a correct sampler is 1e-4 per
  histogram). Negative control: values bent by ``u^1.15`` fail it.
* Stratified: for 64 samples of a pixel, each of the 64 cells of every elementary grid
  (``2^a x 2^b``, ``a + b = 6``) of a 2-D draw holds one sample; for 1-D draws each of the
  64 intervals; also for samples 64..127 (``zsobol``: for a pixel's whole block of 128, as
  pbrt's ZSobolSampler stratifies the spp rounded up to a power of two) and for dimensions
  of a later bounce. Negative control: PCG32's values are not.
* Renders are unbiased: drpt with ``--sampler ldsampler`` against Mitsuba by the 8x8 block
  z-test (``|z| < 4.5``, image mean ``|z| < 4``, as the corpus tests); drpt's per-pixel
  variance comes from the samples' squares, which for correlated (stratified) samples
  overestimates the variance of the mean, so the test is conservative. Negative control:
  a sampler whose 2-D draws reuse their first dimension as their second (every pair on the
  diagonal) fails it.
* Deterministic for a seed; a chunked render equals the plain one bit for bit.
* The independent sampler's PCG32 streams (``pcg_streams``, the renderer's camera passes)
  are independent from lane to lane: the pairs of values of lanes ``i`` and ``i + lag``
  (first with first, second with second, first with second draw; lags 1, 2, 3, 4, 64 and
  256: a pixel's neighbouring samples and the same sample of the neighbouring pixels)
  fill an 8x8 histogram as uniform pairs do, chi-square p > 1e-6 each (a fixed key).
  Negative control: Dr.Jit's ``PCG32(n, initstate, initseq)`` (lane ``i``: state and
  increment plus ``i``), which the renderer used before, fails it by far.
"""

from __future__ import annotations

from dataclasses import replace

import drjit as dr
import numpy as np
import pytest
from drjit.auto import PCG32, Array2f, UInt32, UInt64
from scipy.stats import chi2

from drpt.render.sampler import LDSampler, ZSobolSampler, pcg_streams, sobol1_reversed
from support.corpus import check_scene
from support.xml import sampler_scene


def _sobol1_matrix(i: int) -> int:
    r, v = 0, 1 << 31
    while i:
        if i & 1:
            r ^= v
        i >>= 1
        v ^= v >> 1
    return r


def test_sobol_second_dimension_matches_its_generator_matrix():
    idx = np.random.default_rng(1).integers(0, 1 << 32, 500, dtype=np.uint64).astype(np.uint32)
    idx[:4] = (0, 1, 2, 0xFFFFFFFF)
    got = dr.brev(sobol1_reversed(UInt32(idx))).numpy()
    assert (got == np.array([_sobol1_matrix(int(i)) for i in idx], np.uint32)).all()


def _draws(seed: int, pixels: int, spp: int, start: int = 0, skip: int = 0, kind: str = "ldsampler"):
    """One 1-D draw and one 2-D draw (after ``skip`` dimensions) of ``spp`` samples from
    ``start`` of each of ``pixels`` pixels (of a 64-pixel-wide image for ``zsobol``):
    numpy ``(pixels, spp)`` arrays ``u, x, y``."""
    lane = dr.arange(UInt32, pixels * spp)
    pixel, index = lane // spp, lane % spp + start
    if kind == "zsobol":
        cls = ZSobolSampler.for_image(64, -(-pixels // 64), start + spp)
        s = cls.for_pixels_xy(seed, pixel % 64, pixel // 64, index)
    else:
        s = LDSampler.for_pixels(seed, pixel, index)
    for _ in range(skip):
        s.next_float32()
    u = s.next_float32()
    p = s.next_2d()
    return (u.numpy().reshape(pixels, spp), p.x.numpy().reshape(pixels, spp),
            p.y.numpy().reshape(pixels, spp))


def _chi2_p(counts: np.ndarray) -> float:
    expected = counts.sum() / counts.size
    stat = ((counts - expected) ** 2 / expected).sum()
    return float(chi2.sf(stat, counts.size - 1))


def _uniform_p(u, x, y, bend=1.0):
    u, x, y = u ** bend, x ** bend, y ** bend
    p1 = _chi2_p(np.histogram(u, 64, (0, 1))[0])
    p2 = _chi2_p(np.histogram2d(x, y, 16, ((0, 1), (0, 1)))[0])
    return p1, p2


@pytest.mark.parametrize("kind", ["ldsampler", "zsobol"])
@pytest.mark.parametrize("skip", [0, 37])
def test_values_are_uniform(skip, kind):
    u, x, y = _draws(5, 16384, 4, skip=skip, kind=kind)
    # one sample per pixel: pixels' scrambles are independent, so the values are too
    p1, p2 = _uniform_p(u[:, 1], x[:, 1], y[:, 1])
    assert p1 > 1e-4 and p2 > 1e-4, (p1, p2)
    bent = _uniform_p(u[:, 1], x[:, 1], y[:, 1], bend=1.15)
    assert max(bent) < 1e-4, bent  # negative control


def _stratified(x, y, spp: int) -> bool:
    m = spp.bit_length() - 1
    for a in range(m + 1):
        nx, ny = 1 << a, 1 << (m - a)
        cell = np.floor(x * nx).astype(np.int64) * ny + np.floor(y * ny).astype(np.int64)
        if any(len(set(row)) != spp for row in cell):
            return False
    return True


@pytest.mark.parametrize("kind", ["ldsampler", "zsobol"])
@pytest.mark.parametrize("start,skip", [(0, 0), (64, 0), (0, 20), (128, 41)])
def test_a_pixels_samples_are_stratified(start, skip, kind):
    spp = 64
    if kind == "zsobol":  # its pixel's whole block of 2^m samples (64, or 128: odd m)
        start, spp = 0, 64 if start == 0 else 128
    u, x, y = _draws(11, 50, spp, start, skip, kind)
    assert all(len(set(np.floor(row * spp).astype(int))) == spp for row in u)
    assert _stratified(x, y, spp)
    # negative control: independent samples are not
    rng = PCG32(50 * spp, initstate=UInt64(1))
    xi, yi = rng.next_float32().numpy(), rng.next_float32().numpy()
    assert not _stratified(xi.reshape(50, spp), yi.reshape(50, spp), spp)


def test_deterministic_for_a_seed_and_decorrelated_across_seeds():
    a, b, c = _draws(3, 64, 16), _draws(3, 64, 16), _draws(4, 64, 16)
    assert all((p == q).all() for p, q in zip(a, b))
    assert all((p != q).mean() > 0.9 for p, q in zip(a, c))
    # pixels and dimensions decorrelated
    u, x, _ = _draws(3, 2048, 1)
    assert abs(np.corrcoef(u[:-1, 0], u[1:, 0])[0, 1]) < 0.1
    assert abs(np.corrcoef(u[:, 0], x[:, 0])[0, 1]) < 0.1


class _DiagonalSampler(LDSampler):
    """Negative control: a 2-D draw's second value reuses its first dimension."""

    def next_2d(self):
        p = super().next_2d()
        return Array2f(p.x, p.x)


@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("name,control,kind", [("meshes", False, "ldsampler"), ("lens", False, "ldsampler"),
                                               ("glossy", False, "ldsampler"), ("meshes", True, "ldsampler"),
                                               ("glossy", False, "zsobol"), ("lens", False, "zsobol")])
def test_ldsampler_renders_like_mitsuba(name, control, kind, monkeypatch):
    from drpt.testing import block_z
    from support.xml import XML, load, mean_z, render_xml_both

    if control:
        from drpt.render import renderer

        monkeypatch.setattr(renderer, "LDSampler", _DiagonalSampler)
    scene, _ = load(name)
    r, ref, var = render_xml_both(scene, XML / f"{name}.xml", 256, sampler=kind)
    z = np.abs(block_z(r.image.astype(np.float64), r.variance, ref, var)).max()
    zmean = np.abs(mean_z(r, ref, var)).max()
    if control:
        assert z > 4.5 or zmean > 4.0, (z, zmean)
    else:
        assert z < 4.5 and zmean < 4.0, (z, zmean)


@pytest.mark.slow
@pytest.mark.parametrize("kw", [{}, {"filter": "gaussian"}, {"integrator": "whitted"},
                                {"filter": "tent", "filter_sampling": True}, {"sampler": "zsobol"},
                                {"integrator": "ptracer"}],
                         ids=["path", "gaussian-splatting", "whitted", "filter-sampling", "zsobol", "ptracer"])
def test_chunked_and_resumed_renders_are_the_plain_render(tmp_path, kw):
    """A render in chunks of one sample per pixel, interrupted after 3 chunks and resumed from
    its checkpoint, gives the plain render's image bit for bit; another seed another image."""
    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene
    from support.resume import interrupted_then_resumed

    scene = load_scene("scenes/cornellbox/cornellbox.txt")
    o = RenderOptions(width=16, height=12, spp=12, seed=7, progress=False,
                      max_lanes=16 * 12 * 4, chunk_spp=1, **{"sampler": "ldsampler", **kw})
    plain = Renderer(scene, o).render()
    other = Renderer(scene, replace(o, seed=8)).render()
    assert (plain.image != other.image).any()
    assert np.array_equal(interrupted_then_resumed(scene, o, tmp_path / "cut.exr").result.image, plain.image)


#: Mitsuba corpus scenes rendered with --sampler ldsampler (their files ask for independent)
CORPUS_LD = ("bsdf_spheres/test_arealight_path.xml", "bsdf_spheres/test_textured_roughconductor_path.xml",
             "bsdf_spheres/test_envmap_path.xml", "spot_light/test_spot_direct.xml",
             "various_emitters/test_various_emitters_ptracer.xml")


@pytest.mark.slow
@pytest.mark.parametrize("rel", CORPUS_LD)
def test_corpus_scenes_pass_with_the_ldsampler(rel):
    """Mitsuba's render-test z-test (:mod:`support.corpus`) of corpus scenes rendered with the
    low-discrepancy sampler at 256 spp (skips without ../shared)."""
    t = check_scene(rel, 256, sampler="ldsampler")
    assert t.passed, str(t)


@pytest.mark.slow
def test_corpus_z_test_catches_a_sampler_that_reuses_a_dimension(monkeypatch):
    """Negative control of the corpus test: the diagonal sampler fails it."""
    from drpt.render import renderer

    monkeypatch.setattr(renderer, "LDSampler", _DiagonalSampler)
    t = check_scene(CORPUS_LD[0], 256, sampler="ldsampler")
    assert not t.passed, str(t)




@pytest.mark.parametrize("plugin", ["ldsampler", "stratified", "multijitter", "orthogonal", "independent"])
def test_the_xml_sampler_and_its_seed_are_read(tmp_path, plugin):
    from drpt.options import RenderOptions, with_scene_settings
    from drpt.scene import load_scene

    p = tmp_path / "s.xml"
    p.write_text(sampler_scene(f'<sampler type="{plugin}"><integer name="sample_count" '
                                   'value="16"/><integer name="seed" value="5"/>'
                                   '<boolean name="jitter" value="true"/></sampler>'
                                   if plugin != "independent" else
                                   '<sampler type="independent"><integer name="seed" value="5"/></sampler>'))
    if plugin == "orthogonal":  # Mitsuba rounds 16 up to a square of a prime: 25, and says so
        with pytest.warns(UserWarning, match="sample_count 16 rounded up to 25"):
            scene = load_scene(p)
    else:
        scene = load_scene(p)
    opts, scene = with_scene_settings(RenderOptions(progress=False), scene)
    assert (opts.sampler, opts.seed) == (plugin, 5)


def test_the_command_line_sampler_and_seed_win_over_the_files(tmp_path):
    import argparse

    from drpt.cli.args import add_render_flags, given_settings, options_from_args
    from drpt.options import with_scene_settings
    from drpt.scene import load_scene

    p = tmp_path / "s.xml"
    p.write_text(sampler_scene('<sampler type="ldsampler"><integer name="seed" value="5"/></sampler>'))
    parser = argparse.ArgumentParser()
    add_render_flags(parser)
    scene = load_scene(p)
    args = parser.parse_args(["--sampler", "independent", "--seed", "2"])
    opts, _ = with_scene_settings(options_from_args(args), scene, given_settings(args))
    assert (opts.sampler, opts.seed) == ("independent", 2)
    args = parser.parse_args([])
    opts, _ = with_scene_settings(options_from_args(args), scene, given_settings(args))
    assert (opts.sampler, opts.seed) == ("ldsampler", 5)


def test_light_tracing_beyond_2_32_paths_says_it_draws_independent_samples():
    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    scene = load_scene("scenes/cornellbox/cornellbox.txt")
    o = RenderOptions(width=65536, height=65536, spp=2, progress=False, sampler="ldsampler", integrator="ptracer")
    r = Renderer(scene, o)
    assert not r.ld_sampling and any("2^32 paths" in w and "independent" in w for w in r.warnings)
    r = Renderer(scene, replace(o, spp=1))
    assert r.ld_sampling and not r.warnings


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["ldsampler", "zsobol"])
def test_the_wavefront_mode_traces_the_megakernels_samples(kind):
    """With a low-discrepancy sampler a sample's random numbers depend on its pixel, index and
    dimension only, so the wavefront mode (one path per lane) and the megakernel (path
    regeneration: 4 paths a lane here) give the same image, to float rounding (1e-5).
    Negative control: independent samples (streams per lane) do not."""
    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    scene = load_scene("scenes/newscene/newscene.txt")
    o = RenderOptions(width=48, height=48, spp=32, seed=5, progress=False, sampler=kind)
    mega = Renderer(scene, o).render().image
    assert np.abs(Renderer(scene, replace(o, mode="wavefront")).render().image - mega).max() < 1e-5
    ind = replace(o, sampler="independent")
    assert np.abs(Renderer(scene, replace(ind, mode="wavefront")).render().image
                  - Renderer(scene, ind).render().image).max() > 1e-2


def test_light_sample_reuse_keeps_the_selection_and_rescales_uniformly():
    """AreaLights.reuse: the primitive picked from u.x is the one u.x picks, and u.x rescaled
    to its CDF interval is uniform on [0, 1) among the samples that pick it (chi-square of 32
    bins at p > 1e-4; negative control: the un-rescaled u.x is not)."""
    from drjit.auto import Bool, Float

    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    r = Renderer(load_scene("tests/data/xml/sphere_light.xml"), RenderOptions(width=4, height=4, spp=1,
                                                                              progress=False))
    lights = r.scene.area_lights
    assert lights.count > 2
    n = 1 << 16
    u = Array2f(Float((np.arange(n) + 0.5) / n), Float(np.full(n, 0.5)))
    active = dr.full(Bool, True, n)
    sel, v = lights.reuse(u, active)
    k0, _ = lights._select(u.x, active)
    k1, _ = lights._select(sel, active)
    k0, k1, x, ux = k0.numpy(), k1.numpy(), v.x.numpy(), u.x.numpy()
    assert (k0 == k1).all() and (x >= 0).all() and (x < 1).all() and (v.y.numpy() == 0.5).all()
    for k in np.unique(k0):
        mine = k0 == k
        if mine.sum() >= 32 * 20:
            assert _chi2_p(np.histogram(x[mine], 32, (0, 1))[0]) > 1e-4
            assert _chi2_p(np.histogram(ux[mine], 32, (0, 1))[0]) < 1e-4  # negative control


@pytest.mark.mitsuba
def test_sample_counts_round_as_mitsubas_samplers_do():
    """drpt's reader takes the sample count Mitsuba's sampler plugins round ``sample_count``
    to (ldsampler: square powers of two; stratified: squares; multijitter: r x ceil(n / r);
    orthogonal: squares of primes), asked of Mitsuba's own plugins."""
    import mitsuba as mi

    from drpt.backend import mitsuba_variant
    from drpt.scene.mitsuba.reader import mitsuba_sample_count

    mi.set_variant(mitsuba_variant())
    for plugin in ("independent", "ldsampler", "stratified", "multijitter", "orthogonal"):
        for n in (1, 2, 5, 10, 16, 17, 50, 64, 100):
            expected = mi.load_dict({"type": plugin, "sample_count": n}).sample_count()
            assert mitsuba_sample_count(plugin, n) == expected, (plugin, n)


def test_the_image_does_not_depend_on_the_pass_layout():
    """A pixel's samples are its sequence's indices 0..spp-1 whatever the passes, lanes per
    pixel and path regeneration: renders with other max_lanes agree to float rounding
    (1e-6, the sums' order). Negative control: independent samples do not (their streams
    are the pass's and the lane's)."""
    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    scene = load_scene("scenes/cornellbox/cornellbox.txt")
    for kind in ("ldsampler", "zsobol"):
        o = RenderOptions(width=16, height=16, spp=16, seed=5, progress=False, sampler=kind)
        ref = Renderer(scene, o).render().image
        for lanes in (64, 256, 16 * 16 * 3):  # bands of rows, 1 and 3 samples per pixel a pass
            assert np.abs(Renderer(scene, replace(o, max_lanes=lanes)).render().image - ref).max() < 1e-6
    ind = replace(o, sampler="independent")
    assert np.abs(Renderer(scene, replace(ind, max_lanes=256)).render().image
                  - Renderer(scene, ind).render().image).max() > 1e-3


def test_zsobol_beyond_32_index_bits_draws_from_the_ldsampler_with_a_warning():
    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    scene = load_scene("scenes/cornellbox/cornellbox.txt")
    big = Renderer(scene, RenderOptions(width=4096, height=2048, spp=512, progress=False, sampler="zsobol"))
    assert big._zsobol is None and any("32 bits" in w for w in big.warnings), big.warnings
    fits = Renderer(scene, RenderOptions(width=4096, height=2048, spp=256, progress=False, sampler="zsobol"))
    assert fits._zsobol is not None and not any("32 bits" in w for w in fits.warnings)


@pytest.mark.parametrize("w,h,spp,lanes", [(7, 5, 11, 40), (7, 5, 11, 1000), (16, 12, 9, 64), (5, 3, 4, 10)])
def test_passes_first_samples_number_every_sample_once(w, h, spp, lanes):
    """PassPlan.first_sample (light tracing's path index in its one sequence): the passes'
    ranges ``first .. first + k rows W`` cover 0 .. W H spp - 1 once each."""
    from drpt.render.renderer import plan_passes

    plan = plan_passes(w, h, spp, lanes)
    seen = []
    for i, (_s0, k, _r0, rows) in enumerate(plan):
        seen += range(plan.first_sample(i), plan.first_sample(i) + k * rows * w)
    assert sorted(seen) == list(range(w * h * spp))


_LAGS = (1, 2, 3, 4, 64, 256)


def _worst_pair_chi2(rng, n: int) -> float:
    """The largest chi-square (63 dof) of the 8x8 histograms of ``(u_i, u_{i+lag})`` over
    the first two draws of ``n`` lanes of ``rng`` (first-first, second-second, first-second)."""
    a, b = rng.next_float32().numpy(), rng.next_float32().numpy()
    worst = 0.0
    for lag in _LAGS:
        for x, y in ((a, a), (b, b), (a, b)):
            h, _, _ = np.histogram2d(x[:-lag], y[lag:], bins=8, range=[[0, 1], [0, 1]])
            e = (n - lag) / 64
            worst = max(worst, float(((h - e) ** 2 / e).sum()))
    return worst


def test_pcg_streams_of_neighbouring_lanes_are_independent():
    n = 1 << 18
    limit = chi2.ppf(1 - 1e-6, 63)
    assert _worst_pair_chi2(pcg_streams(n, 0x243F6A8885A308D3), n) < limit


def test_the_renderers_camera_streams_are_pcg_streams(cornell):
    """A camera pass's lanes (a pixel's samples adjacent, its neighbours' ``k`` lanes
    away) draw from :func:`pcg_streams` of ``(seed, pass)``."""
    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer, _mix_seed
    from drpt.scene import load_scene

    r = Renderer(load_scene(cornell), RenderOptions(width=16, height=16, spp=4, seed=3, sampler="independent",
                                                    progress=False))
    n, lane, x, y = r._pass_lanes(4, 0, 16)
    got = r._sampler(2, n, x, y, lane % 4, 1)
    want = pcg_streams(n, _mix_seed(3, 2))
    assert np.array_equal(got.next_float32().numpy(), want.next_float32().numpy())
    assert np.array_equal(got.next_float32().numpy(), want.next_float32().numpy())


def test_arange_seeded_pcg_streams_fail_the_independence_test():
    """Negative control: Dr.Jit's own per-lane streams (state and increment ``+ i``)."""
    n = 1 << 18
    limit = chi2.ppf(1 - 1e-6, 63)
    rng = PCG32(n, initstate=UInt64(0x243F6A8885A308D3), initseq=UInt64(0))
    assert _worst_pair_chi2(rng, n) > 10 * limit


def test_skip_draws_jumps_a_pcg32_past_its_draws():
    """skip_draws moves a PCG32 past ``count`` draws in one step, and the copy it returns draws
    what the stream would have drawn: the same values, then the same state. Negative control:
    a jump one draw short leaves another state. An LDSampler is left as it is (None)."""
    from drpt.render.sampler import skip_draws

    rng, ref = pcg_streams(64, 11), pcg_streams(64, 11)
    want = [ref.next_float32() for _ in range(7)]
    start = skip_draws(rng, 7)
    got = [start.next_float32() for _ in range(7)]
    assert all(np.array_equal(a.numpy(), b.numpy()) for a, b in zip(got, want))
    assert np.array_equal(rng.state.numpy(), ref.state.numpy())
    assert np.array_equal(start.state.numpy(), ref.state.numpy())
    short = pcg_streams(64, 11)
    skip_draws(short, 6)
    assert not np.array_equal(short.state.numpy(), ref.state.numpy())
    ld = LDSampler.for_pixels(1, dr.arange(UInt32, 4), dr.zeros(UInt32, 4))
    assert skip_draws(ld, 7) is None


def test_ldsampler_fields_take_the_widest_fields_width():
    """A wide ``step`` with one ``key`` and ``index`` for all lanes widens them (and ``dim``)
    to its width, the values broadcast; so does a wide ``key`` a width-1 ``step``."""
    s = LDSampler(UInt32(7), UInt32(3), dr.arange(UInt32, 5) + 1)
    assert [dr.width(v) for v in (s.key, s.index, s.step, s.dim)] == [5] * 4
    assert list(s.key) == [7] * 5 and list(s.index) == [3] * 5 and list(s.step) == [1, 2, 3, 4, 5]
    s = LDSampler(dr.arange(UInt32, 4), UInt32(0), UInt32(2))
    assert [dr.width(v) for v in (s.key, s.index, s.step, s.dim)] == [4] * 4 and list(s.step) == [2] * 4
