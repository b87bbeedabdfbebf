"""Mitsuba's stratified, multijitter and orthogonal samplers (drpt.render.sampler:
``permute``, ``Stratified``, ``Multijitter``, ``Orthogonal``, ``strata_sampler``).

* ``permute`` is a bijection of ``0 .. n - 1`` for every seed, and a uniformly random one: the
  24 permutations of 4 elements over 4800 seeds, where each of 7 elements goes over 14000
  seeds, and where two elements go together (n = 8, 16, 121; 20000 seeds) pass a chi-square
  test at p > 1e-4 (fixed seeds; a correct permutation fails each with probability 1e-4).
  Negative control: 2 rounds of the hash instead of 5 fail them all.
* Stratified as claimed, for a pixel's ``count`` samples (block 0 and block 1, first and later
  dimensions): ``stratified``, one sample in each of the ``res x res`` cells of a 2-D draw and
  in each ``1 / count`` interval of a 1-D draw; ``multijitter``, one in each of its
  ``nx x ny`` cells and its x and y values one in each ``1 / count`` interval (also for a
  non-square 12); ``orthogonal`` of strength 2 over a prime ``p``, any two of the dimensions
  ``0 .. p`` put one sample in each of the ``p x p`` cells, every 1-D value one in each ``1 /
  p^2`` interval; strength 3 (Bush), with all ``p^3`` rows, any three dimensions of ``0 ..
  p - 1`` one in each of the ``p^3`` cells. Negative control: PCG32's values are not stratified.
* Uniform and independent: 1-D (64 bins) and 2-D (16 x 16) histograms of a dimension's values
  over 16384 pixels, and 2-D histograms of pairs of dimensions of one sample, pass a chi-square
  test at p > 1e-4. Negative control: values bent by ``u^1.15``, and a pair that reuses a
  dimension, fail it.
* Renders agree with Mitsuba's own same sampler on ``tests/data/xml/samplers.xml`` (and
  ``veach_mis.xml`` with ``multijitter``) by the 8x8
  block z-test (``|z| < 4.5``, image mean ``|z| < 4``; drpt's variance comes from the samples'
  squares, which for stratified samples overestimates the variance of the mean: the test is
  conservative), and with Mitsuba's corpus references (``../shared``, skips without it).
  Negative control: a sampler whose 2-D draws reuse their first dimension fails both.
* Deterministic for a seed; chunked and resumed renders equal the plain one bit for bit; the
  wavefront mode traces the megakernel's samples; the XML's ``jitter`` and ``strength`` are read.
"""

from __future__ import annotations

import itertools
from dataclasses import replace

import drjit as dr
import numpy as np
import pytest
from drjit.auto import PCG32, Array2f, UInt32, UInt64
from scipy.stats import chi2

from drpt.render import sampler as smp
from drpt.render.sampler import Multijitter, Orthogonal, Stratified, permute, strata_sampler
from support.corpus import check_scene
from support.xml import sampler_scene

KINDS = ("stratified", "multijitter", "orthogonal")


def _chi2_p(counts: np.ndarray) -> float:
    counts = np.asarray(counts, np.float64).ravel()
    expected = counts.sum() / counts.size
    return float(chi2.sf(((counts - expected) ** 2 / expected).sum(), counts.size - 1))


# ------------------------------------------------------------------ the permutation
@pytest.mark.parametrize("n", [1, 2, 3, 4, 7, 9, 16, 17, 100, 289])
def test_permute_is_a_bijection_for_every_seed(n):
    seeds = 40
    x = dr.arange(UInt32, n * seeds) % n
    s = UInt32(np.repeat(np.arange(seeds, dtype=np.uint64) * 2654435761 % (1 << 32), n).astype(np.uint32))
    p = permute(x, n, s).numpy().reshape(seeds, n)
    assert all(sorted(row) == list(range(n)) for row in p)


def _permutation_ps():
    index = {q: i for i, q in enumerate(itertools.permutations(range(4)))}
    seeds = 24 * 200
    x = dr.arange(UInt32, 4 * seeds) % 4
    s = UInt32(np.repeat((np.arange(seeds, dtype=np.uint64) * 2654435761 + 3) % (1 << 32), 4).astype(np.uint32))
    p = permute(x, 4, s).numpy().reshape(seeds, 4)
    whole = _chi2_p(np.bincount([index[tuple(r)] for r in p], minlength=24))
    seeds = 7 * 2000
    x = dr.arange(UInt32, 7 * seeds) % 7
    s = UInt32(np.repeat(np.arange(seeds) + 12345, 7).astype(np.uint32))
    p = permute(x, 7, s).numpy().reshape(seeds, 7)
    where = _chi2_p(np.stack([np.bincount(p[:, k], minlength=7) for k in range(7)]))
    pairs = []
    for n in (8, 16, 121):  # where two elements go together (a power of two: no cycle walking)
        seeds = 20000
        x = dr.arange(UInt32, n * seeds) % n
        s = UInt32(np.repeat(np.arange(seeds) * 7 + 99, n).astype(np.uint32))
        p = permute(x, n, s).numpy().reshape(seeds, n)
        off = [a * n + b for a in range(n) for b in range(n) if a != b]
        pairs += [_chi2_p(np.bincount(p[:, a] * n + p[:, b], minlength=n * n)[off]) for a, b in ((0, 2), (1, 5))]
    return whole, where, min(pairs)


def test_permute_is_uniformly_random(monkeypatch):
    ps = _permutation_ps()
    assert min(ps) > 1e-4, ps
    monkeypatch.setattr(smp, "PERMUTE_ROUNDS", 2)  # negative control: too few rounds
    ps = _permutation_ps()
    assert max(ps) < 1e-4, ps


# ------------------------------------------------------------------ stratification
def _sampler(cls, pixels: int, start: int = 0, seed: int = 11, count: int | None = None):
    """``cls``'s sampler of ``pixels`` pixels with samples ``start .. start + count - 1``."""
    n = count or cls.count
    lane = dr.arange(UInt32, pixels * n)
    return cls.for_pixels(seed, lane // n, lane % n + start)


def _cells(values, res) -> np.ndarray:
    return np.minimum(np.floor(np.asarray(values) * res).astype(np.int64), res - 1)


def _one_each(cells: np.ndarray, count: int) -> bool:
    """Every row (a pixel's samples) holds ``count`` distinct cells."""
    cells = np.asarray(cells)
    return cells.shape[1] == count and bool((np.diff(np.sort(cells, axis=1), axis=1) > 0).all())


@pytest.mark.parametrize("spp,start,skip", [(16, 0, 0), (16, 16, 0), (9, 0, 23), (64, 64, 41)])
def test_stratified_puts_one_sample_in_each_stratum(spp, start, skip):
    cls = strata_sampler("stratified", spp)
    s = _sampler(cls, 30, start)
    for _ in range(skip):
        s.next_float32()
    u = s.next_float32().numpy().reshape(30, spp)
    p = s.next_2d()
    x, y = p.x.numpy().reshape(30, spp), p.y.numpy().reshape(30, spp)
    assert _one_each(_cells(u, spp), spp)
    assert _one_each(_cells(x, cls.res) * cls.res + _cells(y, cls.res), spp)
    # negative control: independent samples are not
    rng = PCG32(30 * spp, initstate=UInt64(1))
    xi, yi = rng.next_float32().numpy().reshape(30, spp), rng.next_float32().numpy().reshape(30, spp)
    assert not _one_each(_cells(xi, cls.res) * cls.res + _cells(yi, cls.res), spp)


@pytest.mark.parametrize("spp,start,skip", [(12, 0, 0), (16, 16, 5), (64, 0, 30)])
def test_multijitter_is_stratified_in_cells_and_in_each_axis(spp, start, skip):
    cls = strata_sampler("multijitter", spp)
    assert (cls.nx * cls.ny, cls.count) == (spp, spp)
    s = _sampler(cls, 30, start)
    for _ in range(skip):
        s.next_float32()
    p = s.next_2d()
    x, y = p.x.numpy().reshape(30, spp), p.y.numpy().reshape(30, spp)
    assert _one_each(_cells(x, cls.nx) * cls.ny + _cells(y, cls.ny), spp)
    assert _one_each(_cells(x, spp), spp) and _one_each(_cells(y, spp), spp)
    rng = PCG32(30 * spp, initstate=UInt64(2))
    xi = rng.next_float32().numpy().reshape(30, spp)
    assert not _one_each(_cells(xi, spp), spp)  # negative control


@pytest.mark.parametrize("spp,start", [(25, 0), (49, 49)])
def test_orthogonal_arrays_of_strength_2_stratify_every_pair_of_dimensions(spp, start):
    cls = strata_sampler("orthogonal", spp)
    p = cls.res
    s = _sampler(cls, 20, start)
    v = np.stack([s.next_float32().numpy().reshape(20, spp) for _ in range(p + 1)])
    for a, b in itertools.combinations(range(p + 1), 2):
        assert _one_each(_cells(v[a], p) * p + _cells(v[b], p), spp), (a, b)
    assert all(_one_each(_cells(v[a], spp), spp) for a in range(p + 1))
    # (Bose's array has p + 1 columns: dimension p + 1 holds dimension 0's column again)
    w = s.next_float32().numpy().reshape(20, spp)
    assert not _one_each(_cells(v[0], p) * p + _cells(w, p), spp)
    rng = PCG32(20 * spp, initstate=UInt64(3))
    xi, yi = rng.next_float32().numpy().reshape(20, spp), rng.next_float32().numpy().reshape(20, spp)
    assert not _one_each(_cells(xi, p) * p + _cells(yi, p), spp)  # negative control


def test_orthogonal_arrays_of_strength_3_stratify_every_triple_of_dimensions():
    """Bush's construction over all ``p^3`` rows (Mitsuba draws ``p^2`` of them: a class
    with ``count = p^3`` takes them all)."""
    base = strata_sampler("orthogonal", 25, True, 3)
    p = base.res
    cls = type("Bush125", (base,), {"count": p ** 3})
    n = p ** 3
    s = _sampler(cls, 8)
    v = np.stack([s.next_float32().numpy().reshape(8, n) for _ in range(p)])
    for a, b, c in itertools.combinations(range(p), 3):
        assert _one_each((_cells(v[a], p) * p + _cells(v[b], p)) * p + _cells(v[c], p), n), (a, b, c)
    assert all(_one_each(_cells(v[a], n), n) for a in range(p))


def test_without_jitter_samples_sit_in_their_strata_s_middle():
    cls = strata_sampler("stratified", 16, False)
    u = _sampler(cls, 4).next_float32().numpy().reshape(4, 16)
    assert np.allclose(np.sort(u, axis=1), (np.arange(16) + 0.5) / 16)
    o = strata_sampler("orthogonal", 25, False)
    v = _sampler(o, 4).next_float32().numpy().reshape(4, 25)
    assert np.allclose(np.sort(v, axis=1), (np.arange(25) + 0.5) / 25, atol=1e-6)
    assert not np.allclose(np.sort(_sampler(strata_sampler("stratified", 16), 4).next_float32().numpy()
                                   .reshape(4, 16), axis=1), (np.arange(16) + 0.5) / 16)


# ------------------------------------------------------------------ uniformity
def _one_per_pixel(kind: str, spp: int, skip: int, seed: int = 5):
    """One sample per pixel of 16384 pixels (sample ``pixel mod count``): a 1-D and a 2-D
    draw after ``skip`` dimensions, and the draws of dimensions 0 .. 13 of the sample."""
    cls = strata_sampler(kind, spp)
    n = 16384
    pixel = dr.arange(UInt32, n)
    s = cls.for_pixels(seed, pixel, pixel % cls.count)
    for _ in range(skip):
        s.next_float32()
    u = s.next_float32().numpy()
    p = s.next_2d()
    s = cls.for_pixels(seed, pixel, pixel % cls.count)
    dims = np.stack([s.next_float32().numpy() for _ in range(14)])
    return u, p.x.numpy(), p.y.numpy(), dims


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("skip", [0, 37])
def test_values_are_uniform_and_dimensions_independent(kind, skip):
    u, x, y, dims = _one_per_pixel(kind, 16, skip)
    p1 = _chi2_p(np.histogram(u, 64, (0, 1))[0])
    p2 = _chi2_p(np.histogram2d(x, y, 16, ((0, 1), (0, 1)))[0])
    assert p1 > 1e-4 and p2 > 1e-4, (p1, p2)
    bent = _chi2_p(np.histogram(u ** 1.15, 64, (0, 1))[0]), _chi2_p(np.histogram2d(
        x ** 1.15, y ** 1.15, 16, ((0, 1), (0, 1)))[0])
    assert max(bent) < 1e-4, bent  # negative control
    for a, b in ((0, 1), (0, 6), (2, 3), (1, 12), (5, 13)):  # (0, 6): orthogonal's wrap at p = 5
        pab = _chi2_p(np.histogram2d(dims[a], dims[b], 16, ((0, 1), (0, 1)))[0])
        assert pab > 1e-4, (a, b, pab)
    assert _chi2_p(np.histogram2d(dims[2], dims[2], 16, ((0, 1), (0, 1)))[0]) < 1e-4  # reused


@pytest.mark.parametrize("kind", KINDS)
def test_deterministic_for_a_seed_and_decorrelated_across_seeds(kind):
    cls = strata_sampler(kind, 16)
    a = _sampler(cls, 64, seed=3).next_2d()
    b = _sampler(cls, 64, seed=3).next_2d()
    c = _sampler(cls, 64, seed=4).next_2d()
    assert (a.x.numpy() == b.x.numpy()).all() and (a.y.numpy() == b.y.numpy()).all()
    assert (a.x.numpy() != c.x.numpy()).mean() > 0.9


# ------------------------------------------------------------------ reading and options


def test_the_xml_jitter_and_strength_are_read_and_the_command_line_wins(tmp_path):
    import argparse

    from drpt.cli.args import add_render_flags, given_settings, options_from_args
    from drpt.options import RenderOptions, with_scene_settings
    from drpt.scene import load_scene

    p = tmp_path / "s.xml"
    p.write_text(sampler_scene('<sampler type="orthogonal"><integer name="sample_count" '
                                   'value="9"/><boolean name="jitter" value="false"/>'
                                   '<integer name="strength" value="3"/></sampler>'))
    opts, _ = with_scene_settings(RenderOptions(progress=False), load_scene(p))
    assert (opts.sampler, opts.spp, opts.jitter, opts.strength) == ("orthogonal", 9, False, 3)
    parser = argparse.ArgumentParser()
    add_render_flags(parser)
    args = parser.parse_args(["--jitter", "on", "--strength", "2"])
    opts, _ = with_scene_settings(options_from_args(args), load_scene(p), given_settings(args))
    assert (opts.sampler, opts.jitter, opts.strength) == ("orthogonal", True, 2)


@pytest.mark.parametrize("strength", ["1", "40"])
def test_a_bad_strength_is_one_located_error(tmp_path, strength):
    from drpt.errors import SceneError
    from drpt.scene import load_scene

    p = tmp_path / "s.xml"
    p.write_text(sampler_scene('<sampler type="orthogonal">'
                                   f'<integer name="strength" value="{strength}"/></sampler>'))
    with pytest.raises(SceneError, match="strength must be at least 2") as e:
        load_scene(p)
    assert "s.xml:5" in str(e.value)


def test_a_render_of_a_count_mitsuba_would_round_says_so():
    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    scene = load_scene("scenes/cornellbox/cornellbox.txt")
    r = Renderer(scene, RenderOptions(width=4, height=4, spp=10, progress=False, sampler="stratified"))
    assert any("16 samples per pixel" in w for w in r.warnings), r.warnings
    r = Renderer(scene, RenderOptions(width=4, height=4, spp=16, progress=False, sampler="stratified"))
    assert not r.warnings


# ------------------------------------------------------------------ renders
def _diagonal(monkeypatch):
    """Negative control: 2-D draws reuse their first dimension as their second."""
    for cls in (Stratified, Multijitter, Orthogonal):
        real = cls.next_2d

        def diag(self, real=real):
            p = real(self)
            return Array2f(p.x, p.x)
        monkeypatch.setattr(cls, "next_2d", diag)


#: (sampler, drpt's spp, Mitsuba's spp per batch of 8): counts each plugin keeps
SPPS = {"stratified": (64, 64), "multijitter": (64, 64), "orthogonal": (49, 49)}


@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("name,kind,control", [("samplers", k, False) for k in KINDS]
                         + [("veach_mis", "multijitter", False), ("samplers", "stratified", True)])
def test_renders_agree_with_mitsubas_same_sampler(name, kind, control, monkeypatch, tmp_path):
    """``samplers.xml`` takes the sampler as ``$sampler``; ``veach_mis.xml`` (no assets) is
    copied with its sampler plugin replaced."""
    from drpt.scene import load_scene
    from drpt.testing import block_z
    from support.xml import XML, mean_z, render_xml_both

    if control:
        _diagonal(monkeypatch)
    spp, ref_batch = SPPS[kind]
    path = XML / f"{name}.xml"
    if name != "samplers":
        text = path.read_text()
        assert '<sampler type="independent">' in text
        path = tmp_path / path.name
        path.write_text(text.replace('<sampler type="independent">', f'<sampler type="{kind}">'))
    defines = {"sampler": kind} if name == "samplers" else {}
    scene = load_scene(path, defines={**defines, "spp": str(spp)})
    r, ref, var = render_xml_both(scene, path, spp, defines=defines, ref_spp=8 * ref_batch)
    z = np.abs(block_z(r.image.astype(np.float64), r.variance, ref, var)).max()
    zmean = np.abs(mean_z(r, ref, var)).max()
    if control:
        assert z > 4.5 or zmean > 4.0, (z, zmean)
    else:
        assert z < 4.5 and zmean < 4.0, (z, zmean)


#: Mitsuba corpus scenes (their files ask for independent samples) and each sampler's spp
CORPUS = ("bsdf_spheres/test_arealight_path.xml", "spot_light/test_spot_direct.xml")


@pytest.mark.slow
@pytest.mark.parametrize("rel,kind", [(CORPUS[0], k) for k in KINDS] + [(CORPUS[1], "multijitter")])
def test_corpus_scenes_pass_with_the_strata_samplers(rel, kind):
    """Mitsuba's render-test z-test (:mod:`support.corpus`) of corpus scenes rendered with
    each sampler (skips without ../shared)."""
    t = check_scene(rel, 289 if kind == "orthogonal" else 256, sampler=kind)
    assert t.passed, str(t)


@pytest.mark.slow
def test_corpus_z_test_catches_a_sampler_that_reuses_a_dimension(monkeypatch):
    _diagonal(monkeypatch)
    t = check_scene(CORPUS[0], 256, sampler="stratified")
    assert not t.passed, str(t)


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["multijitter", "orthogonal"])
def test_chunked_and_resumed_renders_are_the_plain_render(tmp_path, kind):
    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene
    from support.resume import interrupted_then_resumed

    scene = load_scene("scenes/cornellbox/cornellbox.txt")
    o = RenderOptions(width=16, height=12, spp=9, seed=7, progress=False, max_lanes=16 * 12 * 4,
                      chunk_spp=1, sampler=kind)
    plain = Renderer(scene, o).render()
    assert (plain.image != Renderer(scene, replace(o, seed=8)).render().image).any()
    assert np.array_equal(interrupted_then_resumed(scene, o, tmp_path / "cut.exr").result.image, plain.image)


@pytest.mark.slow
@pytest.mark.parametrize("kind", KINDS)
def test_the_image_does_not_depend_on_the_pass_layout_or_mode(kind):
    """A sample's numbers depend on its pixel, index and dimension only: other pass layouts
    (max_lanes) and the wavefront mode give the image to float rounding."""
    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    scene = load_scene("scenes/cornellbox/cornellbox.txt")
    o = RenderOptions(width=16, height=16, spp=16, seed=5, progress=False, sampler=kind)
    ref = Renderer(scene, o).render().image
    for lanes in (64, 16 * 16 * 3):
        assert np.abs(Renderer(scene, replace(o, max_lanes=lanes)).render().image - ref).max() < 1e-5
    assert np.abs(Renderer(scene, replace(o, max_lanes=256, mode="wavefront")).render().image - ref).max() < 1e-5
