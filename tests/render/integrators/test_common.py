"""The direct-light estimator's delta lights by shadow rays of their own (``--delta-lights each``,
:meth:`drpt.render.integrators.common.DirectLight.delta_each`).

* Where the path tracer renders a scene with a delta light and other emitters, the delta
  lights leave the light selection (which picks among the others) and
  :attr:`~drpt.render.scene.DeviceScene.delta_each` holds them; with ``select``, in
  wavefront mode, for the light tracers (also a renderer derived for one from a path
  tracer's), for a scene whose only emitters are delta lights, one with more than
  ``DELTA_EACH_MAX`` of them, and where shadow rays follow through glass, they stay in it.
* Unbiased: the image of a small object lit from afar by a point light, a rectangle light
  and a sky (the corpus's sphere grid in small) is the same with ``each`` and ``select``:
  the two means, 12 seeds of 16 spp each, differ per 4x4 block of pixels by less than 4.5
  standard errors of the difference (the seeds' spread; 64 blocks: |z| > 4.5 by chance has
  probability below 1e-3), and their sums by under 2%. Negative control: the point light
  counted twice (its own shadow ray *and* the selection, the scene's ``delta_each`` set on
  a ``select`` render) reads z up to 66 there and a sum 28% too bright (the test itself: 2.2,
  0.16%; the blocks' squared standard errors sum to 1/12 of ``select``'s).
* The selection is bound (its tables built on the host) only where it changes: not again
  for each seed's derived renderer (control: a scene that forgot what it bound binds on
  every derive).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from drpt.options import RenderOptions
from drpt.render.renderer import Renderer
from drpt.render.scene import DELTA_EACH_MAX, DeviceScene
from drpt.scene.model import Material, PerspectiveCamera, PointLight, Scene, Skybox, Triangles


def far_lights_scene(tmp_path, lights=True):
    """A glossy square at the origin facing the camera, a point light far below it, a
    rectangle light far above it, and a sky (``lights`` False: the point light alone)."""
    from drpt.imageio import write_image

    cam = PerspectiveCamera((-4.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0), 30)
    mats = [Material("grey", kd=(0.3, 0.25, 0.2), ks=(0.5, 0.5, 0.5), ns=200.0),
            Material("lamp", emission=(3.0, 3.0, 3.0))]
    s = 0.7
    square = [[[0, -s, -s], [0, s, -s], [0, s, s]], [[0, -s, -s], [0, s, s], [0, -s, s]]]
    c, a, b = np.array([-4.0, 0.0, 6.0]), np.array([0.0, 2.0, 0.0]), np.array([1.7, 0.0, 1.0])
    lamp = [[c - a - b, c + a - b, c + a + b], [c - a - b, c + a + b, c - a + b]]
    tris = square + (lamp if lights else [])
    scene = Scene(path=None, camera=cam, materials=mats,
                  triangles=Triangles(np.array(tris, float), np.array([0, 0, 1, 1][:len(tris)], np.int32),
                                      shape=np.array([0, 0, 1, 1][:len(tris)])))
    scene.lights.append(PointLight((-4.0, 0.0, -6.0), (300.0, 300.0, 300.0)))
    if lights:
        img = np.ones((16, 32, 3), np.float32) * 0.3
        img[2:4, 8:11] = 30.0
        write_image(tmp_path / "sky.exr", img)
        scene.lights.append(Skybox(tmp_path / "sky.exr"))
    return scene


def test_delta_lights_leave_the_selection_where_the_path_tracer_renders(tmp_path):
    scene = far_lights_scene(tmp_path)
    each = DeviceScene(scene, RenderOptions())
    assert each.delta_each is each.delta_lights
    assert [type(f).__name__ for f in each.emitter_selection.families] == ["AreaLights", "SkyEmitter"]
    for opts in (RenderOptions(delta_lights="select"), RenderOptions(mode="wavefront"),
                 RenderOptions(integrator="ptracer"), RenderOptions(integrator="bdpt")):
        ds = DeviceScene(scene, opts)
        assert ds.delta_each is None, opts
        assert [type(f).__name__ for f in ds.emitter_selection.families] == \
            ["AreaLights", "DeltaLights", "SkyEmitter"], opts
    # a renderer derived with another integrator puts them back (it reads the scene at trace time)
    r = Renderer(scene, RenderOptions(width=8, height=8, spp=1, progress=False))
    assert r.scene.delta_each is not None
    r.derive(RenderOptions(width=8, height=8, spp=1, progress=False, integrator="ptracer"))
    assert r.scene.delta_each is None and len(r.scene.emitter_selection.families) == 3
    r.derive(r.opt)
    assert r.scene.delta_each is not None and len(r.scene.emitter_selection.families) == 2
    many = far_lights_scene(tmp_path)  # more delta lights than DELTA_EACH_MAX: one ray, selected
    many.lights.extend(PointLight((-4.0, 0.1 * i, -6.0), (10.0, 10.0, 10.0)) for i in range(DELTA_EACH_MAX))
    assert DeviceScene(many, RenderOptions()).delta_each is None
    many.lights.pop()
    assert DeviceScene(many, RenderOptions()).delta_each is not None
    alone = DeviceScene(far_lights_scene(tmp_path, lights=False), RenderOptions())
    assert alone.delta_each is None  # (nothing else to select among)
    assert [type(f).__name__ for f in alone.emitter_selection.families] == ["DeltaLights"]


def test_the_selection_is_bound_where_it_changes(tmp_path, monkeypatch):
    """Binding a light selection builds its tables on the host: a renderer derived again with
    the same integrator (each seed of a study) binds none, a switch to the light tracer binds
    the other selection once and the switch back the first again. Control: a scene that
    forgot what it bound binds on every derive."""
    scene = far_lights_scene(tmp_path)
    binds = []
    bind = DeviceScene.set_light_selection

    def counting(self, selection):
        binds.append(selection)
        return bind(self, selection)

    monkeypatch.setattr(DeviceScene, "set_light_selection", counting)
    opts = RenderOptions(width=8, height=8, spp=1, progress=False)
    r = Renderer(scene, opts)
    first = len(binds)
    for seed in range(3):
        r.derive(replace(opts, seed=seed)).render()
    assert len(binds) == first
    r.derive(replace(opts, integrator="ptracer"))
    r.derive(opts)
    assert len(binds) == first + 2 and binds[-1] is binds[first - 1]
    for seed in range(3):  # control: a scene that forgot what it bound binds on every derive
        r.scene.emitter_selection = None
        r.derive(replace(opts, seed=seed))
    assert len(binds) == first + 5


def _mean_and_error(renderer, seeds):
    images = []
    for seed in range(seeds):
        renderer.opt.seed = seed
        images.append(renderer.render().image.astype(np.float64).mean(-1))
    st = np.stack(images)
    h, w = st.shape[1:]
    blocks = st.reshape(seeds, h // 4, 4, w // 4, 4).mean((2, 4))
    return blocks.mean(0), blocks.std(0, ddof=1) / np.sqrt(seeds)


@pytest.mark.parametrize("control", [False, True])
def test_each_renders_the_selections_image(tmp_path, control):
    scene = far_lights_scene(tmp_path)
    opts = RenderOptions(width=32, height=32, spp=16, progress=False, sampler="independent")
    each = Renderer(scene, replace(opts, delta_lights="each"))
    select = Renderer(scene, replace(opts, delta_lights="select"))
    assert each.scene.delta_each is not None and select.scene.delta_each is None
    if control:  # the point light counted twice: its own shadow ray and the selection's
        each = select.derive(select.opt)
        each.scene.delta_each = each.scene.delta_lights
    a, ea = _mean_and_error(each, 12)
    b, eb = _mean_and_error(select, 12)
    if control:
        select.scene.delta_each = None
        b, eb = _mean_and_error(select, 12)
    z = np.abs(a - b) / np.sqrt(ea ** 2 + eb ** 2 + 1e-30)
    ratio = a.sum() / b.sum()
    if control:
        assert z.max() > 4.5 and ratio > 1.02, (z.max(), ratio)
    else:
        assert z.max() < 4.5 and abs(ratio - 1.0) < 0.02, (z.max(), ratio)
