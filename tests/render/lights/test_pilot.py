"""The pilot light selection (drpt/render/lights/pilot.py, ``--light-sampler pilot``).

The scene: a diffuse floor facing the camera, a dim triangle light above it facing down
onto it, and a light ten times as bright beside the floor, facing away from it (its light
reaches nothing the camera sees).

* The measurement: the bright light's second moment is 0 (no pilot estimate gets light from
  it), so it keeps exactly its defensive share ``DEFENSIVE / 2``, and the dim one the rest;
  by the emitted powers (the negative control) the bright one would get over 90%
  (``power`` counts what reaches the floor, :mod:`drpt.render.lights.reach`: nothing).
* The selection draws each slot with the probability it reports (chi-square of 200,000
  draws, p > 1e-3; negative control: the same draws judged by ``uniform``'s probabilities
  fail, p < 1e-9) and ``pmf`` returns the same numbers.
* It takes the candidate whose measured second moment of the direct-light estimate is
  least (the floor: its own rule, which ``mixed`` is there too), and where the relative and the absolute error disagree,
  the one nearest the least of both (two hand-made lanes: ``uniform``); the second moment
  recomputes the MIS weights for each selection (a lane by hand, with negative controls).
* It is deterministic (a fixed pilot seed): two builds give the same probabilities. The
  light tracers (``ptracer``, ``bdpt``) run no pilot: their selection is ``mixed``'s.
* The image is ``uniform``'s in expectation: the mean difference of the floor's pixels at
  64 spp, 32x32, within 4 standard errors (of the differences' spread over the pixels);
  negative control: the pilot's image 10% too dark fails.
"""

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Bool, Float, UInt32
from scipy import stats

from drpt.options import RenderOptions
from drpt.render.lights.pilot import DEFENSIVE, PilotSelection, units
from drpt.render.renderer import Renderer
from drpt.render.scene import DeviceScene
from drpt.scene.model import Material, PerspectiveCamera, Scene, Triangles

CAM = PerspectiveCamera((0, 0, 5), (0, 0, -1), (0, 1, 0), 40)


def _scene():
    floor = [[[-2, -2, 0], [2, -2, 0], [2, 2, 0]], [[-2, -2, 0], [2, 2, 0], [-2, 2, 0]]]
    dim = [[-0.8, -0.3, 1.5], [-0.8, 0.3, 1.5], [-0.2, 0.0, 1.5]]  # normal -z: onto the floor
    bright = [[3, -0.3, 0.7], [3, 0.3, 0.7], [3, 0, 1.3]]  # normal +x: away from it
    return Scene(path=None, camera=CAM,
                 materials=[Material("floor", kd=(0.5, 0.5, 0.5)), Material("dim", emission=(2, 2, 2)),
                            Material("bright", emission=(20, 20, 20))],
                 triangles=Triangles(np.array(floor + [dim, bright], float), np.array([0, 0, 1, 2], np.int32),
                                     shape=np.array([0, 0, 1, 2])))


def _unit_probabilities(ds):
    sel = ds.emitter_selection
    return np.bincount(units(sel.families), weights=sel.probabilities)


@pytest.fixture(scope="module")
def pilot():
    return DeviceScene(_scene(), RenderOptions(light_sampler="pilot", width=32, height=32))


def test_pilot_leaves_the_light_that_misses_the_floor_its_defensive_share(pilot):
    assert isinstance(pilot.emitter_selection, PilotSelection)
    m = pilot.emitter_selection.moments
    assert m[0] > 0.0 and m[1] == 0.0
    np.testing.assert_allclose(_unit_probabilities(pilot), [1.0 - DEFENSIVE / 2, DEFENSIVE / 2], rtol=1e-12)
    # negative control: by their emitted powers (before the share that reaches the floor) the
    # bright light would get over 90%
    lights = DeviceScene(_scene(), RenderOptions(light_sampler="power", width=32, height=32)).area_lights
    emitted = lights._area[lights._ids] * lights._lum[lights._ids]
    assert emitted[1] / emitted.sum() > 0.9


def test_pilot_draws_what_it_reports(pilot):
    sel = pilot.emitter_selection
    rng = np.random.default_rng(3)
    n = 200_000
    k, pmf = sel.sample(Float(rng.random(n).astype(np.float32)), None, dr.full(Bool, True, n))
    k, pmf = k.numpy(), pmf.numpy()
    counts = np.bincount(k, minlength=sel.count)
    assert stats.chisquare(counts, sel.probabilities * n)[1] > 1e-3
    np.testing.assert_allclose(pmf, sel.probabilities[k], rtol=1e-6)
    np.testing.assert_allclose(sel.pmf(UInt32(np.arange(sel.count, dtype=np.uint32))).numpy(),
                               sel.probabilities, rtol=1e-6)
    uni = DeviceScene(_scene(), RenderOptions(light_sampler="uniform")).emitter_selection.probabilities
    assert stats.chisquare(counts, uni * n)[1] < 1e-9  # negative control


def test_pilot_is_deterministic(pilot):
    again = DeviceScene(_scene(), RenderOptions(light_sampler="pilot", width=32, height=32))
    np.testing.assert_array_equal(again.emitter_selection.probabilities, pilot.emitter_selection.probabilities)


def _floor(rule):
    r = Renderer(_scene(), RenderOptions(light_sampler=rule, width=32, height=32, spp=64, seed=5,
                                         progress=False))
    return r.render().image.astype(np.float64)[4:28, 4:28].mean(-1)


def test_pilot_image_is_uniforms_in_expectation(pilot):
    a, b = _floor("pilot"), _floor("uniform")
    floor = (a < 1.0) & (b < 1.0)  # (the lights' own pixels are at least 2)
    for scale in (1.0, 0.9):  # (0.9: the negative control, a 10% bias)
        d = scale * a[floor] - b[floor]
        z = d.mean() / (d.std() / np.sqrt(d.size))
        assert (abs(z) < 4) == (scale == 1.0), (scale, z)


@pytest.mark.parametrize("integrator", ["ptracer", "bdpt"])
def test_light_tracers_run_no_pilot(integrator):
    sel = DeviceScene(_scene(), RenderOptions(light_sampler="pilot", integrator=integrator)).emitter_selection
    assert not isinstance(sel, PilotSelection) and sel.rule == "mixed"


def test_pilot_chooses_the_candidate_with_the_least_second_moment(pilot):
    """On the floor, the pilot's own rule (the dim light 75%) has the least measured second
    moment, relative and absolute, and ``uniform`` (50%) more; ``mixed`` is the pilot's rule
    here (its power counts what reaches the floor, nothing of the bright light:
    :mod:`drpt.render.lights.reach`), so it measures the same; the selection is the least
    one's, the first of the candidates where they tie."""
    sel = pilot.emitter_selection
    c = sel.candidates
    assert set(c) == {"pilot", "pilot absolute", "uniform", "mixed"}
    for i in (0, 1):
        assert c["pilot"][i] < c["uniform"][i], c
        assert c["mixed"][i] == pytest.approx(c["pilot"][i], rel=1e-9), c
    assert sel.choice == "pilot"


def _measurement(**over):
    from drpt.render.lights.pilot import Measurement

    # one lane: next-event estimation picked emitter 0, BSDF sampling reached emitter 1
    base = dict(k=np.array([0]), pmf=np.array([0.5]), nee=np.array([2.0]), e=np.array([0.5]),
                b=np.array([0.5]), delta=np.array([False]), j=np.array([1]), bsdf=np.array([1.0]),
                e_b=np.array([0.25]), b_b=np.array([1.0]), w=np.array([1.0]), uniform=np.array([0.5, 0.5]))
    return Measurement(**{**base, **over})


def test_second_moment_recomputes_the_mis_weights_for_each_selection():
    """By hand: under ``uniform`` the light sample's weight is 1/2 (equal densities) and
    the BSDF sample's 1 / (1 + 1/16); with emitter 0 at 80% the light density doubles
    (x1.6, weight 0.64 / 0.89) and the estimate is reweighted by 1 / 1.6, the BSDF sample's
    emitter density falls to 0.1 (weight 1 / 1.01). Negative controls: weights left at
    ``uniform``'s, a delta light (no MIS weight) and a Dirac BSDF lobe (no MIS weight) each
    change the number."""
    m = _measurement()
    np.testing.assert_allclose(m.second_moment([0.5, 0.5]), 1.0 + (1 / (1 + 1 / 16)) ** 2, rtol=1e-12)
    x = 2.0 * 0.64 / 0.89
    want = x * x / 1.6 + (1 / 1.01) ** 2
    np.testing.assert_allclose(m.second_moment([0.8, 0.2]), want, rtol=1e-12)
    stale = (2.0 * 0.5 / 1.6) ** 2 * 1.6 + (1 / (1 + 1 / 16)) ** 2  # uniform's MIS weights kept
    assert abs(m.second_moment([0.8, 0.2]) - stale) > 0.05
    np.testing.assert_allclose(_measurement(delta=np.array([True])).second_moment([0.5, 0.5]),
                               4.0 + (1 / (1 + 1 / 16)) ** 2, rtol=1e-12)
    np.testing.assert_allclose(_measurement(b_b=np.array([0.0])).second_moment([0.5, 0.5]), 2.0, rtol=1e-12)


def test_pilot_gives_up_neither_error_for_the_other(pilot):
    """Two lanes: a dim film tile (weight 100) lit by emitter 0, a bright one (weight 1e-4)
    by emitter 1 with 100x its estimate. The relative error's least second moment is the
    ``sqrt(M)`` rule's (emitter 0 at 70%; or ``mixed``'s, which gives emitter 0 75% in this
    scene, its bright light reaching nothing), the absolute error's that rule's weighed
    absolutely (emitter 1 at 75%); each is 2.5-2.7x the other's least, ``uniform`` within
    1.5x of both, so the pilot takes ``uniform`` (taking the relative error's best alone
    would be the negative control: ``pilot`` or ``mixed``)."""
    from drpt.render.lights.pilot import PilotSelection

    m = _measurement(k=np.array([0, 1]), pmf=np.array([0.5, 0.5]), nee=np.array([1.0, 100.0]),
                     e=np.array([0.5, 0.5]), b=np.array([0.0, 0.0]), delta=np.array([False, False]),
                     j=np.array([-1, -1]), bsdf=np.zeros(2), e_b=np.zeros(2), b_b=np.zeros(2),
                     w=np.array([100.0, 1e-4]))
    sel = PilotSelection(pilot.emitter_selection.families, m.moments(), m)
    c = sel.candidates
    assert min(c, key=lambda k: c[k][0]) in ("pilot", "mixed") and min(c, key=lambda k: c[k][1]) == "pilot absolute"
    assert sel.choice == "uniform", c
    np.testing.assert_allclose(_unit_probabilities_of(sel), [0.5, 0.5])


def _unit_probabilities_of(sel):
    return np.bincount(units(sel.families), weights=sel.probabilities)
