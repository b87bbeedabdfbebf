"""bdpt's caustic merging (``BDPTIntegrator.merging``, drpt/render/integrators/bdpt.py).

Where it is traced: only in scenes with Dirac lobes and area lights, and not with
``--bdpt-merge off``.

Consistency: the seed's Cornell box with a glass sphere (benchmarks/bdpt_equal_time.py), 32x32,
256 spp, depth 8, rendered with merging on and off with the same seed. The main random stream is
the same in both (the photons draw from a stream of their own) and only the paths camera S+ D S+
light differ, so ``on - off`` is the merged estimate of those paths minus their ``s = 0``
estimate (the camera subpath hitting the light: the path tracer's way of sampling them),
zero in expectation up to merging's bias. Over 12 seeds, per 8x8-pixel block (16 blocks,
channels summed) and over the image: ``z = mean / standard error`` of ``on - off``,
``|z| < 4`` per block and ``< 3`` over the image. The bias at the default radius (0.01 of the
scene's radius), measured over 16 seeds at 32x32 and 256 spp: the merged image total of those
paths is 2.300 +- 0.048 against ``s = 0``'s 2.277 +- 0.119 (radius 0.0025: 2.270, 0.04:
2.318), below the test's resolution, which the thresholds above therefore hold. Negative
control: photons of twice their power fail the image test (z > 10 measured). The renders draw
independent samples (``--sampler independent``), for which the bias and the thresholds above
were measured.
"""

from __future__ import annotations

import importlib.util
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from drpt.options import PathOptions, RenderOptions
from drpt.render.integrators import bdpt as B
from drpt.render.renderer import Renderer
from drpt.scene import load_scene

REPO = Path(__file__).resolve().parents[3]


def _glass_cornell_text() -> str:
    spec = importlib.util.spec_from_file_location("bdpt_equal_time_bench", REPO / "benchmarks" / "bdpt_equal_time.py")
    bench = importlib.util.module_from_spec(spec)
    sys.modules["bdpt_equal_time_bench"] = bench
    spec.loader.exec_module(bench)
    return bench.seed_glass_cornell()


@pytest.fixture(scope="module")
def glass(tmp_path_factory):
    path = tmp_path_factory.mktemp("merge") / "glass_cornell.txt"
    path.write_text(_glass_cornell_text())
    return load_scene(path)


def _opts(merge: bool, seed: int = 1, size: int = 32, spp: int = 256) -> RenderOptions:
    return RenderOptions(width=size, height=size, spp=spp, seed=seed, progress=False, integrator="bdpt",
                         path=PathOptions(max_depth=8), bdpt_merge=merge, sampler="independent")


def test_merging_is_traced_only_where_the_scene_needs_it(glass):
    cornell = load_scene(REPO / "scenes" / "cornellbox" / "cornellbox.txt")
    assert not Renderer(cornell, _opts(True)).integrator.merging  # no Dirac lobes
    assert Renderer(glass, _opts(True)).integrator.merging
    assert not Renderer(glass, _opts(False)).integrator.merging


def test_the_radius_shrinks_per_sample_as_progressive_photon_mapping_s(glass):
    """Per sample ``s`` (a pass of one sample per pixel) the squared radius follows Knaus and
    Zwicker's recurrence; a pass of ``k`` samples merges at the mean of its samples' squared
    radii. Negative control: the pass's first sample's radius alone differs."""
    integ = Renderer(glass, _opts(True)).integrator
    r = [integ.merge_radius(s, 1) for s in range(200)]
    assert r[0] == pytest.approx(B.MERGE_RADIUS * integ.rays.radius)
    for s in range(199):
        assert (r[s + 1] / r[s]) ** 2 == pytest.approx((s + 1 + B.MERGE_ALPHA) / (s + 2), rel=1e-9)
    # r_s^2 ~ s^(alpha - 1): the ratio of squared radii over a factor 10 of samples
    assert (r[199] / r[19]) ** 2 == pytest.approx((200 / 20) ** (B.MERGE_ALPHA - 1.0), rel=0.03)
    for first, k in ((0, 256), (16, 16), (100, 37)):
        mean = np.mean([x * x for x in r[first:first + k]] if first + k <= 200
                       else [integ.merge_radius(s, 1) ** 2 for s in range(first, first + k)])
        assert integ.merge_radius(first, k) ** 2 == pytest.approx(mean, rel=1e-9)
        assert integ.merge_radius(first, k) < 0.999 * r[first]


def _radii(scene, monkeypatch, **extra) -> list[tuple[int, int, float]]:
    """``(first, k, radius)`` of each photon map a bdpt render of ``scene`` builds (one per
    pass; its pilot, the path tracer's, builds none)."""
    seen = []
    photons = B.BDPTIntegrator.photons

    def recording(self, rng, m, first, k):
        grid = photons(self, rng, m, first, k)
        seen.append((first, k, grid.radius))
        return grid

    monkeypatch.setattr(B.BDPTIntegrator, "photons", recording)
    Renderer(scene, replace(_opts(True, size=16, spp=16), **extra)).render()
    monkeypatch.undo()
    return seen


def test_the_radius_follows_the_samples_per_pixel_not_the_passes(glass, monkeypatch):
    """A 16x16, 16 spp render in one pass and in four (``max_lanes`` of 4 samples per
    pixel) merges each pass at the mean squared radius of its
    samples, so the mean of ``r^2`` over all samples is the same in both: the per-sample
    schedule's mean over the 16 samples. Negative control: the old rule (the pass's sample
    step as the schedule's index) gives the two layouts different means."""
    integ = Renderer(glass, _opts(True)).integrator
    want = np.mean([integ.merge_radius(s, 1) ** 2 for s in range(16)])
    one = _radii(glass, monkeypatch)
    many = _radii(glass, monkeypatch, max_lanes=16 * 16 * 4)
    # the passes' maps (the pilot is the path tracer's: it traces none)
    assert [(f, k) for f, k, _ in one] == [(0, 16)]
    assert [(f, k) for f, k, _ in many] == [(4 * i, 4) for i in range(4)]
    for seen in (one, many):
        assert all(r == integ.merge_radius(f, k) for f, k, r in seen)
        passes = seen
        mean = sum(k * r * r for _, k, r in passes) / sum(k for _, k, _r in passes)
        assert mean == pytest.approx(want, rel=1e-9)
    old = [integ.merge_radius(0, 1) ** 2 * np.prod([(i + B.MERGE_ALPHA) / (i + 1) for i in range(1, step + 1)])
           for step in range(4)]
    assert abs(np.mean(old) - integ.merge_radius(0, 1) ** 2) > 0.05 * integ.merge_radius(0, 1) ** 2


def test_bdpt_merge_needs_bdpt(tmp_path, capsys):
    from drpt.cli import main

    scene = REPO / "scenes" / "cornellbox" / "cornellbox.txt"
    code = main(["render", str(scene), "--size", "8", "8", "--spp", "1", "-q", "--bdpt-merge", "on",
                 "-o", str(tmp_path / "x.exr")])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--bdpt-merge needs --integrator bdpt" in err[0]


def test_bdpt_strategies_refuse_explicit_merging(tmp_path, capsys):
    """The strategy images render without merging: an explicit ``--bdpt-merge on`` with
    ``--bdpt-strategies`` is one clear line, exit 2 (``off`` or none renders)."""
    from drpt.cli import main

    scene = REPO / "scenes" / "cornellbox" / "cornellbox.txt"
    args = ["render", str(scene), "--size", "8", "8", "--spp", "1", "-q", "--integrator", "bdpt",
            "--bdpt-strategies", "-o", str(tmp_path / "x.exr")]
    assert main([*args, "--bdpt-merge", "on"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--bdpt-strategies renders without caustic merging" in err[0], err
    assert main([*args, "--bdpt-merge", "off"]) == 0


#: glass (thin panes) + plastic + an area light: the camera sees the plastic floor through a
#: pane, and in the floor's coating the light behind a pane below it (camera S D S light with
#: a Dirac lobe sampled at D)
PLASTIC = """<scene version="3.0.0">
    <sensor type="perspective"><float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0, 1, 5" target="0, 0, -1" up="0, 1, 0"/></transform></sensor>
    <bsdf type="thindielectric" id="pane"><float name="int_ior" value="1.5"/></bsdf>
    <shape type="rectangle"><transform name="to_world"><scale x="2" y="2"/><translate y="0.5" z="3.5"/></transform>
        <ref id="pane"/></shape>
    <shape type="rectangle"><transform name="to_world"><scale value="4"/><rotate x="1" angle="-90"/></transform>
        <bsdf type="plastic"><rgb name="diffuse_reflectance" value="0.5, 0.5, 0.5"/></bsdf></shape>
    <shape type="rectangle"><transform name="to_world"><rotate x="1" angle="90"/><translate y="1.4" z="-1"/></transform>
        <ref id="pane"/></shape>
    <shape type="rectangle"><transform name="to_world"><scale value="0.6"/><rotate x="1" angle="90"/>
        <translate y="1.5" z="-1"/></transform><emitter type="area"><rgb name="radiance" value="10"/></emitter></shape>
</scene>
"""


@pytest.fixture(scope="module")
def plastic(tmp_path_factory):
    path = tmp_path_factory.mktemp("merge") / "plastic.xml"
    path.write_text(PLASTIC)
    return load_scene(path)


def _difference_z(glass, monkeypatch=None, power_scale: float = 1.0, seeds: int = 12, size: int = 32,
                  spp: int = 256):
    """``(max |z| over the blocks, |z| of the image)`` of ``on - off`` (module docstring), at
    ``size x size`` pixels in 4 x 4 blocks."""
    if power_scale != 1.0:
        photons = B.BDPTIntegrator.photons

        def scaled(self, rng, n, first, k):
            grid = photons(self, rng, n, first, k)
            grid.fields["power"] = grid.fields["power"] * power_scale
            return grid

        monkeypatch.setattr(B.BDPTIntegrator, "photons", scaled)
    diffs = []
    for seed in range(1, seeds + 1):
        on = Renderer(glass, _opts(True, seed, size, spp)).render().image.astype(np.float64)
        off = Renderer(glass, _opts(False, seed, size, spp)).render().image.astype(np.float64)
        diffs.append((on - off).sum(-1))
    d = np.stack(diffs)  # (seeds, H, W)
    b = size // 4
    blocks = d.reshape(seeds, 4, b, 4, b).sum((2, 4)).reshape(seeds, -1)
    total = d.sum((1, 2))

    def z(x):
        se = x.std(0, ddof=1) / np.sqrt(seeds)
        return np.where(se > 0, x.mean(0) / np.where(se > 0, se, 1.0), 0.0)

    return float(np.abs(z(blocks)).max()), float(abs(z(total)))


@pytest.mark.slow
def test_merged_caustics_agree_with_hitting_the_light(glass):
    zb, zt = _difference_z(glass)
    assert zb < 4.0 and zt < 3.0, (zb, zt)


@pytest.mark.slow
def test_merging_negative_control_photons_of_twice_their_power(glass, monkeypatch):
    zb, zt = _difference_z(glass, monkeypatch, power_scale=2.0)
    assert zt > 6.0, (zb, zt)


@pytest.mark.slow
def test_a_dirac_lobe_sampled_at_the_merged_vertex_keeps_its_light_hit(plastic):
    """With plastic at the merged vertex D, a path whose camera subpath samples the coating
    there (camera S D S light: the light seen in the coating through panes) is not one that
    merging estimates (it evaluates the smooth lobes only): ``s = 0`` keeps it, and merging
    on and off agree, as on the glass Cornell box (the same z-test: 16x16 pixels, 64 spp,
    12 seeds, ``|z| < 4`` per block, ``< 3`` over the image). Dropping those hits instead
    (the phase from the material alone) loses the reflection: z = 23 over the image, 31 per
    block, measured; with the rule, 0.2 and 2.2."""
    zb, zt = _difference_z(plastic, size=16, spp=64)
    assert zb < 4.0 and zt < 3.0, (zb, zt)


@pytest.mark.slow
def test_plastic_negative_control_photons_of_twice_their_power(plastic, monkeypatch):
    zb, zt = _difference_z(plastic, monkeypatch, power_scale=2.0, size=16, spp=64)
    assert zt > 6.0, (zb, zt)


# ------------------------------------------------------------ chunks, workers, resume
@pytest.mark.slow
def test_merging_in_chunks_and_resumed_gives_the_plain_image(glass, monkeypatch, tmp_path):
    """A render in chunks merges each chunk at the radius of its own samples' indices in the
    whole render (``first`` is the chunk's first sample, not 0), so the image does not depend on
    where the render was cut: interrupted after 2 of 4 chunks and resumed, it is the plain
    render's image bit for bit (float32). The radius is 10x the default so that a 16x16, 8 spp
    render merges at all (at the default no pixel of it does); Dask workers, other processes,
    would not see that patch, and trace the same chunk function (test_bdpt.py checks their
    images). Negative control: merging off gives another image, so merged paths are in it."""
    from support.resume import interrupted_then_resumed

    monkeypatch.setattr(B, "MERGE_RADIUS", 10 * B.MERGE_RADIUS)
    opts = replace(_opts(True, size=16, spp=8), chunk_spp=2)
    seen = []
    photons = B.BDPTIntegrator.photons

    def recording(self, rng, m, first, k):
        seen.append((first, k))
        return photons(self, rng, m, first, k)

    with monkeypatch.context() as m:
        m.setattr(B.BDPTIntegrator, "photons", recording)
        plain = Renderer(glass, opts).render()
    assert seen == [(0, 2), (2, 2), (4, 2), (6, 2)]  # (the pilot is the path tracer's: no photons)
    assert not np.array_equal(Renderer(glass, replace(opts, bdpt_merge=False)).render().image, plain.image)
    resumed = interrupted_then_resumed(glass, opts, tmp_path / "cut.exr", after=2).result
    assert np.array_equal(resumed.image, plain.image)
