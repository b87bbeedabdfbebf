"""Russian roulette below a throughput threshold (``PathOptions.rr_threshold``,
drpt/render/integrators/path.py ``continue_path``): before ``rr_depth`` a path whose
throughput is below the threshold continues with probability throughput / threshold and
survivors are divided by it, so the image's expectation is that of Mitsuba's rule alone."""

from dataclasses import replace

import drjit as dr
import numpy as np
import pytest

import drpt.render.integrators.path as path_module
from drpt.options import RR_THRESHOLD, PathOptions, RenderOptions, with_scene_settings
from drpt.render.renderer import Renderer
from drpt.scene import load_scene
from drpt.testing import block_z

#: dark diffuse spheres (reflectance 0.1) on a grey floor under a constant sky and a small
#: area light: after one bounce off a sphere the throughput is 0.1, so with the threshold at 1
#: roulette plays at nearly every vertex before rr_depth
DARK_XML = """<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="-1"/></integrator>
  <sensor type="perspective"><float name="fov" value="45"/>
    <transform name="to_world"><lookat origin="0, -4, 2.5" target="0, 0, 0.3" up="0, 0, 1"/></transform>
    <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="24"/>
      <rfilter type="box"/></film>
    <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
  </sensor>
  <emitter type="constant"><rgb name="radiance" value="0.6, 0.7, 0.9"/></emitter>
  <bsdf type="diffuse" id="dark"><rgb name="reflectance" value="0.1, 0.08, 0.06"/></bsdf>
  <bsdf type="diffuse" id="grey"><rgb name="reflectance" value="0.5"/></bsdf>
  <shape type="sphere"><point name="center" x="-0.7" y="0" z="0.6"/><float name="radius" value="0.6"/>
    <ref id="dark"/></shape>
  <shape type="sphere"><point name="center" x="0.8" y="0.4" z="0.5"/><float name="radius" value="0.5"/>
    <ref id="dark"/></shape>
  <shape type="rectangle"><transform name="to_world"><scale value="4"/></transform><ref id="grey"/></shape>
  <shape type="rectangle"><transform name="to_world"><scale value="0.4"/><rotate x="1" angle="180"/>
    <translate z="3"/></transform><emitter type="area"><rgb name="radiance" value="20"/></emitter></shape>
</scene>"""

SPP = 256


def _render(scene, threshold: float, seed: int):
    opts = RenderOptions(width=32, height=24, spp=SPP, seed=seed, progress=False, sampler="independent",
                         path=PathOptions(rr_threshold=threshold))
    return Renderer(scene, opts).render()


@pytest.fixture(scope="module")
def dark_scene(tmp_path_factory):
    p = tmp_path_factory.mktemp("rr") / "dark.xml"
    p.write_text(DARK_XML)
    return load_scene(p)


@pytest.fixture(scope="module")
def without(dark_scene):
    """Mitsuba's rule alone (threshold 0), 256 spp."""
    return _render(dark_scene, 0.0, seed=1)


def test_roulette_below_the_threshold_keeps_the_image(dark_scene, without, monkeypatch):
    """Threshold 1 (roulette wherever the throughput is below 1: every path off the dark
    spheres) against threshold 0, other seeds: every 4x4 block's mean agrees within 4.5
    combined standard errors (each image's own variance estimate), and roulette played (the
    variance grows). Negative control: survivors not divided by the probability (an
    estimator that loses the light of the paths roulette ends) fails by far."""
    assert np.isfinite(without.image).all() and without.image.mean() > 0.05
    played = _render(dark_scene, 1.0, seed=2)
    z = block_z(played.image, played.variance, without.image, without.variance, block=4)
    assert np.abs(z).max() < 4.5, np.abs(z).max()
    assert played.variance.mean() > 1.05 * without.variance.mean()

    original = path_module.continue_path

    def biased(scene, opt, si, s, rng, u=None, sampled=None):
        # the same survival test, the survivors' throughput left as it was
        wo, bs, beta, eta, depth, live = original(scene, replace(opt, rr_threshold=0.0), si, s, rng, u, sampled)
        early = dr.max(beta) * dr.square(eta)  # (threshold 1)
        live &= (depth >= opt.rr_depth) | (u[2] < early)
        return wo, bs, beta, eta, depth, live

    monkeypatch.setattr(path_module, "continue_path", biased)
    wrong = _render(dark_scene, 1.0, seed=2)
    zw = block_z(wrong.image, wrong.variance, without.image, without.variance, block=4)
    assert np.abs(zw).max() > 8.0, np.abs(zw).max()
    assert wrong.image.mean() < 0.98 * without.image.mean()


def test_threshold_zero_is_mitsubas_rule_bit_for_bit(dark_scene, without):
    """Threshold 0 traces no early roulette: the image of a render whose paths never fall
    below a tiny threshold (1e-30) is the same, bit for bit."""
    np.testing.assert_array_equal(_render(dark_scene, 1e-30, seed=1).image, without.image)


def test_a_mitsuba_xml_renders_with_mitsubas_rule_unless_given(dark_scene):
    """The default is :data:`RR_THRESHOLD` for drpt's own formats; a Mitsuba XML scene's
    integrator is Mitsuba's (threshold 0) unless the command line gives one."""
    assert PathOptions().rr_threshold == RR_THRESHOLD > 0.0
    opts, _ = with_scene_settings(RenderOptions(), dark_scene)
    assert opts.path.rr_threshold == 0.0
    given = RenderOptions(path=PathOptions(rr_threshold=0.3))
    opts, _ = with_scene_settings(given, dark_scene, {"rr_threshold"})
    assert opts.path.rr_threshold == 0.3


@pytest.mark.parametrize("argv, expected", [([], RR_THRESHOLD), (["--rr-threshold", "0.25"], 0.25),
                                            (["--rr-threshold", "0"], 0.0)])
def test_the_flag(argv, expected):
    from drpt.cli import build_parser
    from drpt.cli.args import given_settings, options_from_args

    ns = build_parser().parse_args(["render", "scene.txt", *argv])
    assert options_from_args(ns).path.rr_threshold == expected
    assert ("rr_threshold" in given_settings(ns)) == bool(argv)
