"""The wavefront volpath (drpt/render/integrators/volwavefront.py) against the megakernel's
(drpt/render/integrators/volpath.py).

* Same estimator, path by path: with the same lane streams the wavefront's ``sample``
  returns the megakernel's for every lane (float rounding aside: measured identical) on
  the bundled cornellbox_media (medium queue, glass and null boundaries, a fog layer),
  with the fused tail, a depth limit with hidden emitters, a fixed roulette probability,
  and on corpus participating_media scenes (a heterogeneous medium, whose shadow rays are
  traced inside the queues; null boundaries under an envmap; a spot light through rough
  glass; an emitter inside a medium), which skip without ../shared.
* Same estimator, statistically: renders by the two modes at different seeds (the
  megakernel with path regeneration) agree by the block z-test of drpt/testing.py (max
  |z| < 4.5 over 8x8 blocks of 32x32 images, whose blocks hold 64 x spp samples each);
  negative controls: the wavefront image scaled by 1 -+ 6% fails (cornellbox_media, whose
  fog and caustics make its blocks noisy: 4% reads |z| 4.1-5.0), and so does a medium
  stage whose scattering keeps 70% of the throughput it should (a wrong albedo, as a bug in
  that stage would give; 85% reads |z| 4.8, too close to the threshold to be a control).
* A pass of at most 2^14 samples traces one path per lane in both modes: the same image.
* Determinism: the same seed gives the same bits (with and without the coherence sort);
  chunked renders are pure and ``--workers`` gives the plain image bit for bit.
* The queues: the medium queue traces no BSDF code and the surface queues no phase
  function; a scene without media still gets the path integrator's wavefront.
"""

from __future__ import annotations

import warnings
from dataclasses import replace

import drjit as dr
import numpy as np
import pytest
from drjit.auto import PCG32, Bool, Float, UInt32

from drpt.options import PathOptions, RenderOptions, with_scene_settings
from drpt.render.integrators import volpath as vp
from drpt.render.integrators import wavefront as wf
from drpt.render.integrators.volwavefront import VolWavefrontIntegrator
from drpt.render.renderer import Renderer
from drpt.scene import load_scene
from drpt.testing import block_z
from support import SCENES
from support.corpus import corpus_scene

ZMAX = 4.5
BLOCK = 8
MEDIA = SCENES / "cornellbox_media" / "cornellbox_media.txt"
# corpus scenes (participating_media/) for the path-by-path and statistical checks
HETERO = "participating_media/test_hetero_sigmat_albedo_volpath.xml"
NULL_ENV = "participating_media/test_homo_null_envmap_volpath.xml"
SPOT = "participating_media/test_homo_roughdielectric_spot_volpath.xml"
INSIDE = "participating_media/test_homo_emitter_inside_medium_volpath.xml"


def _load(name: str):
    if name == "cornellbox_media":
        return load_scene(MEDIA)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_scene(corpus_scene(name), defines={"spp": "4"})


def _opts(scene, **kw) -> RenderOptions:
    base = with_scene_settings(RenderOptions(progress=False, integrator="volpath"), scene)[0]
    return replace(base, **{"width": 32, "height": 32, "spp": 4, "seed": 3, **kw})


def _render(scene, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return Renderer(scene, _opts(scene, **kw)).render()


def _lane_rays(r: Renderer, n: int, seed: int):
    W = r.opt.width
    px = dr.arange(UInt32, n) % (W * r.opt.height)
    rng = PCG32(n, initstate=seed)
    o, d = r.camera.ray(Float(px % W) + rng.next_float32(), Float(px // W) + rng.next_float32())
    return rng, o, d


def _rgb(v) -> np.ndarray:
    return np.stack([c.numpy() for c in (v.x, v.y, v.z)], -1)


PATH_CASES = [("cornellbox_media", 0, {}, ()), ("cornellbox_media", 512, {}, ()),
              ("cornellbox_media", 0, {"max_depth": 4, "hide_emitters": True}, ()),
              ("cornellbox_media", 0, {"rr_prob": 0.7, "rr_depth": 1}, (pytest.mark.slow,)),
              (HETERO, 0, {}, (pytest.mark.slow,)), (HETERO, 512, {}, (pytest.mark.slow,)),
              (NULL_ENV, 0, {}, ()), (SPOT, 0, {}, ()), (INSIDE, 0, {}, ())]


@pytest.mark.parametrize("name,tail,path", [
    pytest.param(n, t, p, marks=m, id=f"{n.split('/')[-1]}-tail{t}-{'-'.join(p) or 'default'}")
    for n, t, p, m in PATH_CASES])
def test_same_paths_as_the_megakernel(name, tail, path):
    scene = _load(name)
    r = Renderer(scene, _opts(scene))
    opt = replace(r.opt.path, **path) if path else r.opt.path
    n = 4096
    rng, o, d = _lane_rays(r, n, 5)
    a = _rgb(vp.VolPathIntegrator(r.scene, opt, scene).sample(rng, o, d, Bool(True)))
    rng, o, d = _lane_rays(r, n, 5)
    integ = VolWavefrontIntegrator(r.scene, opt, scene, tail=tail)
    integ.stats = wf.WaveStats()
    b = _rgb(integ.sample(rng, o, d, Bool(True)))
    assert a.max() > 0.1  # lit
    assert np.all(np.isfinite(b))
    np.testing.assert_allclose(b, a, rtol=1e-4, atol=1e-6)
    stages = integ.stats.stages
    assert "medium" in stages and "shade" in stages  # both kinds of events were queued
    assert ("fused tail" in stages) == (tail > 0)
    assert ("shadow rays" in stages) == (not integ.inline_shadows)  # (heterogeneous: in the queues)


def test_same_image_where_the_megakernel_runs_one_path_per_lane():
    """32 x 32 x 8 = 8192 samples, under the megakernel's 2^14 lanes: it traces one path
    per lane on the wavefront's streams."""
    scene = _load("cornellbox_media")
    a = _render(scene, spp=8).image
    b = _render(scene, spp=8, mode="wavefront").image
    assert a.mean() > 1e-2
    np.testing.assert_allclose(b, a, rtol=1e-5, atol=1e-7)


def _zmax(x, ref) -> float:
    return float(np.abs(block_z(x.image, x.variance, ref.image, ref.variance, block=BLOCK)).max())


#: scene -> spp of the statistical comparison (cornellbox_media's fog makes its blocks noisy)
STAT_CASES = {"cornellbox_media": 256, NULL_ENV: 64, SPOT: 64, HETERO: 64}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(STAT_CASES), ids=lambda n: n.split("/")[-1])
def test_agrees_with_the_megakernel_statistically(name):
    scene = _load(name)
    spp = STAT_CASES[name]
    mk = _render(scene, spp=spp, seed=1)
    wv = _render(scene, spp=spp, seed=2, mode="wavefront")
    assert mk.nonfinite == 0 and wv.nonfinite == 0
    assert wv.image.mean() > 1e-2
    z = _zmax(wv, mk)
    assert z < ZMAX, z
    if name == "cornellbox_media":  # the test's power: a 6% bias fails (measured |z| 5.7-6.4)
        for f in (0.94, 1.06):
            bad = replace(wv, image=f * wv.image, variance=f * f * wv.variance)
            assert _zmax(bad, mk) > ZMAX, (f, z)


@pytest.mark.slow
def test_a_wrong_medium_stage_is_caught(monkeypatch):
    """Negative control: the medium queue's events keep 70% of the throughput (as a wrong
    albedo would); the z-test against the megakernel fails."""
    scene = _load("cornellbox_media")
    mk = _render(scene, spp=256, seed=1)
    event = VolWavefrontIntegrator._event

    def wrong(self, qscene, s, si, fl):
        out, live, q, add = event(self, qscene, s, si, fl)
        if fl.medium:
            out.beta = out.beta * 0.7
        return out, live, q, add

    monkeypatch.setattr(VolWavefrontIntegrator, "_event", wrong)
    bad = _render(scene, spp=256, seed=2, mode="wavefront")
    assert _zmax(bad, mk) > ZMAX


@pytest.mark.slow
def test_deterministic_for_a_seed_and_the_sort_changes_no_bit():
    scene = _load("cornellbox_media")
    a = _render(scene, mode="wavefront", seed=9)
    b = _render(scene, mode="wavefront", seed=9)
    c = _render(scene, mode="wavefront", seed=10)
    assert np.array_equal(a.image, b.image) and np.array_equal(a.variance, b.variance)
    assert not np.array_equal(a.image, c.image)
    r = Renderer(scene, _opts(scene, mode="wavefront", seed=9))
    r.integrator.sort = False
    assert np.array_equal(r.render().image, a.image)


def test_queues_trace_only_their_events(monkeypatch):
    """The medium queue calls no BSDF, the surface queues no phase function, and only the
    megakernel mixes them."""
    scene = _load("cornellbox_media")
    r = Renderer(scene, _opts(scene, mode="wavefront"))
    assert isinstance(r.integrator, VolWavefrontIntegrator)
    calls: list[tuple[str, str]] = []
    current = [None]
    for fn in ("eval_bsdf", "sample_bsdf"):
        orig = getattr(type(r.scene), fn)
        monkeypatch.setattr(type(r.scene), fn, lambda self, *a, _o=orig, _f=fn: (calls.append((current[0], _f)),
                                                                             _o(self, *a))[1])
    for fn in ("hg_pdf", "hg_sample"):
        orig = getattr(vp, fn)
        monkeypatch.setattr(vp, fn, lambda *a, _o=orig, _f=fn: (calls.append((current[0], _f)), _o(*a))[1])
    event = r.integrator._event

    def tagged(qscene, s, si, fl):
        current[0] = "medium" if fl.medium else "surface"
        out = event(qscene, s, si, fl)
        current[0] = None
        return out

    monkeypatch.setattr(r.integrator, "_event", tagged)
    r.render()
    got = set(calls)
    assert ("medium", "hg_sample") in got and ("surface", "sample_bsdf") in got
    assert not {c for c in got if c[0] == "medium" and "bsdf" in c[1]}, got
    assert not {c for c in got if c[0] == "surface" and c[1].startswith("hg")}, got


def test_a_scene_without_media_runs_the_path_wavefront(cornell):
    r = Renderer(load_scene(cornell), RenderOptions(width=8, height=8, spp=1, progress=False,
                                                    integrator="volpath", mode="wavefront"))
    assert type(r.integrator) is wf.WavefrontIntegrator


def test_wavefront_is_refused_only_for_the_light_tracers():
    from drpt.errors import DrptError

    RenderOptions(mode="wavefront", integrator="volpath").validate()
    for integrator in ("whitted", "ptracer", "bdpt"):
        with pytest.raises(DrptError, match="--mode wavefront runs the path and volpath integrators"):
            RenderOptions(mode="wavefront", integrator=integrator).validate()


def test_cli_render(tmp_path):
    from drpt.cli import main

    out = tmp_path / "wf.exr"
    assert main(["render", str(MEDIA), "--size", "8", "8", "--spp", "2", "--mode", "wavefront",
                 "--wavefront-tail", "16", "-q", "-o", str(out)]) == 0
    assert out.is_file()


@pytest.mark.slow
def test_chunks_are_pure():
    """What --resume relies on: a chunk's sums are a pure function of the scene, the
    options and the chunk (the same bits again, and from another renderer)."""
    scene = _load("cornellbox_media")
    opts = _opts(scene, width=16, height=16, spp=8, chunk_spp=2, mode="wavefront")
    a, b = Renderer(scene, opts), Renderer(_load("cornellbox_media"), opts)
    first = a.render_chunk(1)
    for again in (a.render_chunk(1), b.render_chunk(1)):
        assert np.array_equal(first.sum, again.sum) and np.array_equal(first.sumsq, again.sumsq)


@pytest.mark.slow
def test_workers_give_the_plain_image_bit_for_bit(tmp_path):
    pytest.importorskip("distributed")
    from drpt.cli import main
    from drpt.imageio import read_image

    def render(name, *flags):
        out = tmp_path / f"{name}.exr"
        assert main(["render", str(MEDIA), "--size", "16", "16", "--spp", "8", "--chunk-spp", "2",
                     "--mode", "wavefront", "-q", "-o", str(out), *flags]) == 0
        return read_image(out)

    plain = render("plain")
    assert plain.mean() > 1e-2
    assert np.array_equal(plain, render("w2", "--workers", "2"))


def test_path_options_reach_the_wavefront():
    scene = _load("cornellbox_media")
    r = Renderer(scene, _opts(scene, mode="wavefront", path=PathOptions(max_depth=3)))
    assert r.integrator.opt.max_depth == 3 and r.integrator._fused.opt.max_depth == 3
