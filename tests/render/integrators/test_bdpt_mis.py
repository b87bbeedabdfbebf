"""bdpt converts its subpaths' densities to area measure by the length of each segment from the
true previous vertex (:func:`drpt.render.integrators.bdpt.segment_length2`), as its connections
and next-event estimation measure theirs, not by the hit's ray distance ``si.t`` from the
spawned origin (the vertex moved off its surface by :mod:`drpt.render.spawn`'s offset, which
grows with the coordinates' magnitude).

* :func:`segment_length2` is the squared distance from the vertex, not ``si.t``.

No render-level test at ``max_depth`` 2: there the two lengths agree by construction (the light
subpaths' hits are measured from their vertex, :meth:`DeviceScene.intersect_from
<drpt.render.scene.DeviceScene.intersect_from>`, and the camera's first segment starts at the
camera); the far scene renders like the scene at the origin
(tests/render/integrators/test_far_light_paths.py; docs/performance.md, "bdpt's segment
lengths").
"""

from __future__ import annotations

import drjit as dr
import numpy as np
from drjit.auto import Array3f, Bool

import drpt.render.integrators.bdpt as bdpt
from drpt.options import PathOptions, RenderOptions
from drpt.render.renderer import Renderer
from drpt.render.scene import DeviceScene
from support.mis import FAR, floor_scene


def test_the_segment_length_is_measured_from_the_vertex():
    """From a floor point of the far scene, a ray spawned toward the light: ``segment_length2``
    is the squared distance from the floor point itself (relative 1e-5), which ``si.t``, from
    the spawned origin, is not (control: more than 1e-3 off)."""
    scene = DeviceScene(floor_scene(FAR), RenderOptions(width=4, height=4, spp=1))
    n = 64
    x = dr.linspace(dr.auto.Float, 0.035, 0.08, n)  # beside the light (x + y > 1/32)
    ref = Array3f(x, 0.01, FAR)
    d = dr.normalize(Array3f(0.005 - x, 0.0, 1 / 64))  # toward the light's interior
    below = scene.intersect(ref + Array3f(0, 0, 0.5), Array3f(0, 0, -1), Bool(True))
    si = scene.intersect(scene.spawn(below, d), d, Bool(True))
    assert dr.all(below.valid & si.valid & (si.material == 1))
    want = np.sum((np.array(si.p) - np.array(below.p)) ** 2, axis=0)
    got = np.array(bdpt.segment_length2(si, below.p))
    assert np.allclose(got, want, rtol=1e-5, atol=0)
    assert np.max(np.abs(np.array(dr.square(si.t)) / want - 1)) > 1e-3


def test_both_subpath_loops_measure_their_segments_from_the_vertex(monkeypatch):
    """A bdpt render of the far scene (``max_depth`` 3) converts its densities with
    :func:`segment_length2` in both subpath loops (two calls per trace: the light loop's body
    and the camera loop's; with one loop on ``si.t`` the count is 1), and its image depends on
    it: with ``si.t`` in its place the image is another (the weights differ at the far scene's
    spawn offsets)."""
    calls = []

    def counted(si, ref):
        calls.append(1)
        return dr.squared_norm(si.p - ref)

    opts = RenderOptions(width=16, height=16, spp=4, seed=1, progress=False, integrator="bdpt",
                         sampler="independent", path=PathOptions(max_depth=3))
    monkeypatch.setattr(bdpt, "segment_length2", counted)
    image = Renderer(floor_scene(FAR), opts).render().image
    assert len(calls) == 2, len(calls)
    assert image.mean() > 0.0
    monkeypatch.setattr(bdpt, "segment_length2", lambda si, ref: dr.square(si.t))
    control = Renderer(floor_scene(FAR), opts).render().image
    assert not np.array_equal(image, control)
