"""What of an emitter's power reaches the lit geometry (drpt/render/lights/reach.py).

* :meth:`Receivers.isotropic` is the share of uniformly distributed directions from a point
  that enter the sphere, and :meth:`Receivers.flat` the share of cosine-distributed
  directions from a flat source that enter it where the sphere is above the source's
  horizon (0 where it is below): each against 400,000 directions (fixed seed), within 4
  binomial standard errors. Negative control: the same estimates 5% high fail the same
  check.
* :func:`receivers` bounds the shapes that emit nothing (emissive triangles and spheres
  left out) and is ``None`` with infinite planes; their cross-section along a direction
  is the triangles' projected area (both sides) plus the spheres' disks, and the sky's is
  its mean over all directions (against 400,000 directions within 0.5%; negative control:
  5% high fails), each at most the bounding sphere's.
* In a scene whose point light, rectangle light and sky light a small object from afar (the
  corpus's sphere grids), the ``power`` selection's probabilities are the reaching powers'
  shares: the selection's draws pass the chi-square test against them (200,000 draws,
  p > 1e-3); negative control: the same draws judged by the emitted powers' shares (the
  point light's ``4 pi I``) fail (p < 1e-9). Both selections render the same image: the
  ``mixed`` and ``uniform`` renders of that scene agree (max |block z| < 4.5), and the
  test catches a selection that reports other probabilities than it draws (a ``mixed``
  render whose tables hold its probabilities in reverse order: max |block z| > 6).
"""

import math

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Bool, Float
from scipy import stats

from drpt.options import PathOptions, RenderOptions
from drpt.render.lights.reach import Receivers, receivers
from drpt.render.lights.selection import LightSelection
from drpt.render.renderer import Renderer
from drpt.render.scene import DeviceScene
from drpt.scene.model import (
    Material,
    PerspectiveCamera,
    Planes,
    PointLight,
    Scene,
    Skybox,
    Spheres,
    Triangles,
)
from drpt.testing import block_z

N = 400_000


def _uniform_directions(rng, n):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def _cosine_directions(rng, n, normal):
    """Cosine-distributed directions about unit ``normal``."""
    u1, u2 = rng.random(n), rng.random(n)
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    local = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(np.maximum(0.0, 1 - u1))], 1)
    a = np.cross(normal, [0.3, 0.5, 0.8])
    a /= np.linalg.norm(a)
    b = np.cross(normal, a)
    return local @ np.stack([a, b, normal])


def _enter(p, d, c, r):
    """Whether rays from ``p`` along unit ``d`` enter the sphere ``(c, r)``."""
    oc = np.asarray(c) - p
    t = d @ oc
    return (t > 0) & (oc @ oc - t * t < r * r)


def _within(share, hits, n=N, sigmas=4.0):
    se = math.sqrt(max(share * (1 - share), 1e-12) / n)
    return abs(hits.mean() - share) < sigmas * se


REC = Receivers(np.array([0.5, -0.2, 0.3]), 1.3)
POINTS = [(6.0, 1.0, -2.0), (0.5, -0.2, 2.1), (-1.5, 2.0, 1.5)]


@pytest.mark.parametrize("scale", [1.0, 1.05])
def test_isotropic_share_is_the_directions_that_enter(scale):
    rng = np.random.default_rng(7)
    ok = []
    for p in POINTS:
        d = _uniform_directions(rng, N)
        ok.append(_within(scale * float(REC.isotropic(p)[0]), _enter(np.asarray(p), d, REC.center, REC.radius)))
    assert all(ok) if scale == 1.0 else not any(ok), ok  # control: 5% high fails at every point


@pytest.mark.parametrize("scale", [1.0, 1.05])
def test_flat_share_is_the_cosine_directions_that_enter(scale):
    rng = np.random.default_rng(8)
    ok = []
    for p, tilt in zip(POINTS, (0.0, 0.5, 0.9)):
        p = np.asarray(p)
        toward = (REC.center - p) / np.linalg.norm(REC.center - p)
        side = np.cross(toward, [0.3, 0.5, 0.8])
        n = toward * math.cos(tilt) + side / np.linalg.norm(side) * math.sin(tilt)
        assert np.linalg.norm(REC.center - p) * math.cos(tilt) > REC.radius  # above the horizon
        share = scale * float(REC.flat(p, n)[0])
        ok.append(_within(share, _enter(p, _cosine_directions(rng, N, n), REC.center, REC.radius)))
        assert REC.flat(p, -n)[0] == 0.0  # facing away: the sphere below its horizon
    assert all(ok) if scale == 1.0 else not any(ok), ok


def test_inside_the_receivers_everything_reaches_them():
    assert REC.isotropic([0.6, -0.1, 0.2])[0] == 1.0
    assert REC.flat([0.6, -0.1, 0.2], [0.0, 0.0, 1.0])[0] == 1.0


@pytest.mark.parametrize("scale", [1.0, 1.05])
def test_cross_sections_are_the_triangles_projected_areas(scale):
    """``across(d)`` is the triangles' projected area along ``d``, both sides, plus the
    spheres' disks; the sky's ``cross_section`` its mean over uniform directions (400,000,
    fixed seed, within 0.5%); negative control: 5% high fails."""
    rng = np.random.default_rng(9)
    tris = rng.normal(size=(6, 3, 3))
    scene = Scene(path=None, camera=PerspectiveCamera((0, 0, 9), (0, 0, -1), (0, 1, 0), 40),
                  materials=[Material("grey")], triangles=Triangles(tris, np.zeros(6, np.int32)),
                  spheres=Spheres(np.array([[0.5, 0.0, 0.0]]), np.array([0.3]), np.array([0], np.int32)))
    rec = receivers(scene)
    an = 0.5 * np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    d = np.array([0.2, -0.7, 0.4])
    exact = np.abs(an @ (d / np.linalg.norm(d))).sum() + np.pi * 0.09
    assert rec.across(d) == pytest.approx(min(exact, np.pi * rec.radius ** 2), rel=1e-12)
    dirs = _uniform_directions(rng, N)
    mean = np.abs(dirs @ an.T).sum(1).mean() + np.pi * 0.09
    assert (abs(scale * rec.cross_section / mean - 1.0) < 0.005) == (scale == 1.0), (rec.cross_section, mean)
    assert rec.cross_section < np.pi * rec.radius ** 2  # (not the bound)
    # a closed mesh counts both sides: the bounding sphere's cross-section bounds it
    small = Receivers(rec.center, 0.1, tris, None, rec.spheres)
    assert small.across(d) == pytest.approx(np.pi * 0.01) and small.cross_section == pytest.approx(np.pi * 0.01)


def _tri(lo, hi):
    return [[lo, lo, 0.0], [hi, lo, 0.0], [hi, hi, 0.0]]


def test_receivers_bound_what_emits_nothing():
    cam = PerspectiveCamera((0, 0, 5), (0, 0, -1), (0, 1, 0), 40)
    mats = [Material("grey"), Material("lamp", emission=(2.0, 2.0, 2.0))]
    scene = Scene(path=None, camera=cam, materials=mats,
                  triangles=Triangles(np.array([_tri(-1.0, 1.0), _tri(10.0, 12.0)], float), np.array([0, 1], np.int32)),
                  spheres=Spheres(np.array([[0.0, 0.0, 2.0], [0.0, 50.0, 0.0]]), np.array([0.5, 3.0]),
                                  np.array([0, 1], np.int32)))
    rec = receivers(scene)
    np.testing.assert_allclose(rec.center, [0.0, 0.0, 1.25])
    assert rec.radius == pytest.approx(0.5 * math.sqrt(2.0 ** 2 + 2.0 ** 2 + 2.5 ** 2))
    scene.planes = Planes(np.array([[0.0, 0.0, 1.0]]), np.array([0.0]), np.array([0], np.int32))
    assert receivers(scene) is None


# ------------------------------------------------------- a small object lit from afar
def far_lights_scene(tmp_path):
    """The corpus's sphere grid in small: a diffuse square at the origin facing the camera,
    a point light far below it, a rectangle light far above it, and a sky."""
    from drpt.imageio import write_image

    cam = PerspectiveCamera((-4.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0), 30)
    mats = [Material("grey", kd=(0.6, 0.5, 0.4)), Material("lamp", emission=(3.0, 3.0, 3.0))]
    s = 0.7
    square = [[[0, -s, -s], [0, s, -s], [0, s, s]], [[0, -s, -s], [0, s, s], [0, -s, s]]]
    c, a, b = np.array([-4.0, 0.0, 6.0]), np.array([0.0, 2.0, 0.0]), np.array([1.7, 0.0, 1.0])
    lamp = [[c - a - b, c + a - b, c + a + b], [c - a - b, c + a + b, c - a + b]]
    scene = Scene(path=None, camera=cam, materials=mats,
                  triangles=Triangles(np.array(square + lamp, float), np.array([0, 0, 1, 1], np.int32),
                                      shape=np.array([0, 0, 1, 1])))
    img = np.ones((16, 32, 3), np.float32) * 0.3
    img[2:4, 8:11] = 30.0
    write_image(tmp_path / "sky.exr", img)
    scene.lights += [PointLight((-4.0, 0.0, -6.0), (300.0, 300.0, 300.0)), Skybox(tmp_path / "sky.exr")]
    return scene


def _emitter_shares(sel):
    unit = [np.full(f.count, i) for i, f in enumerate(sel.families)]
    return np.bincount(np.concatenate(unit), weights=sel.probabilities)


@pytest.mark.parametrize("control", [False, True])
def test_power_selection_draws_the_reaching_powers(tmp_path, control):
    scene = far_lights_scene(tmp_path)
    ds = DeviceScene(scene, RenderOptions(light_sampler="power", delta_lights="select"))
    sel = ds.emitter_selection
    assert [type(f).__name__ for f in sel.families] == ["AreaLights", "DeltaLights", "SkyEmitter"]
    # the point light's 4 pi I reaches the square through its share of directions
    rec = receivers(scene)
    assert ds.delta_lights.power()[0] == pytest.approx(4 * math.pi * 300.0 * rec.isotropic((-4, 0, -6))[0])
    p = sel.probabilities
    if control:  # the emitted powers: the point light's 4 pi I, the sky over the whole scene's sphere
        lo, hi = scene.bounds()
        big = float(np.linalg.norm(hi - lo)) / 2.0
        emitted = np.concatenate([np.pi * ds.area_lights._area[ds.area_lights._ids] * 3.0, [4 * math.pi * 300.0],
                                  ds.sky.power() * (big / ds.sky.radius) ** 2])
        p = emitted / emitted.sum()
        # the point light's share: reaching, emitted
        assert _emitter_shares(sel)[1] < 0.7 < 0.8 < p[2], (_emitter_shares(sel), p)
    rng = np.random.default_rng(3)
    n = 200_000
    k, _ = sel.sample(Float(rng.random(n).astype(np.float32)), None, dr.full(Bool, True, n))
    counts = np.bincount(np.asarray(k.numpy()), minlength=sel.count)
    pvalue = stats.chisquare(counts, p * counts.sum())[1]
    assert (pvalue < 1e-9) if control else (pvalue > 1e-3), (pvalue, counts, p)


class _Misreported(LightSelection):
    """``mixed``'s draws with its probabilities in the tables in reverse order, each slot's
    density that of another (a negative control)."""

    def __init__(self, families):
        super().__init__(families, "mixed")
        self.probabilities = self.probabilities[::-1].copy()
        self._pmf = Float(self.probabilities.astype(np.float32))


@pytest.mark.slow
@pytest.mark.parametrize("control", [False, True])
def test_mixed_renders_the_uniform_image(tmp_path, control):
    scene = far_lights_scene(tmp_path)
    opts = dict(width=32, height=32, spp=256, path=PathOptions(max_depth=3), progress=False)
    images = {}
    for rule in ("uniform", "mixed"):
        r = Renderer(scene, RenderOptions(light_sampler=rule, seed=1 if rule == "mixed" else 2, **opts))
        if control and rule == "mixed":
            r.scene.set_light_selection(_Misreported(r.scene.emitter_selection.families))
        images[rule] = r.render()
    a, b = images["uniform"], images["mixed"]
    z = np.abs(block_z(a.image, a.variance, b.image, b.variance, block=4)).max()
    assert (z > 6.0) if control else (z < 4.5), z
