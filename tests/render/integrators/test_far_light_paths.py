"""Light subpaths far from the origin (ptracer, bdpt): the far floor scene of the MIS tests
(:func:`support.mis.floor_scene` at :data:`support.mis.FAR`, a floor lit by a small light 1/64
above it) renders as the same scene at ``z = 0``.

A light subpath's rays leave each vertex from its spawned origin, the vertex moved off its
surface by :mod:`drpt.render.spawn`'s offset (at ``z = 4096`` two float32 spacings, 9.8e-4: 6%
of the light's height); their hits are taken as the rays from the vertex itself meet them
(:meth:`drpt.render.scene.DeviceScene.intersect_from`), and each vertex's connection to the
camera is traced from the camera (:func:`drpt.render.integrators.ptracer.camera_segment`).
Hits of the rays from the spawned origins are those of a light 6% lower, which lights less of
the floor that the camera sees around it (docs/performance.md, "Light subpaths far from the
origin").

Thresholds: over :data:`SEEDS` paired seeds (32x32, 16 spp, ``max_depth`` 2, independent
sampler) the relative differences far / origin - 1 have a mean within :data:`T_MAX` standard
errors of 0 (t(7) exceeds 5 with probability 0.2%; measured t -1.0 and -1.6) and within
:data:`MARGIN`, with :data:`T_SPARE` standard errors to spare (a one-sided bound of t(7) at
99.5%; measured means -0.001% and -0.002%). Negative control: the hits of the rays from the
spawned origins (``intersect`` in ``intersect_from``'s place) are darker by more than
:data:`MARGIN` at ``t < -5`` (measured -2.15% and -1.35%, t -33 and -19); the camera
connections' shadow rays from the spawned origins (:func:`support.mis.spawned_segment`) are brighter at
``t > 5`` (measured +0.054% and +0.055%, t 7.0 both).
"""

from __future__ import annotations

import numpy as np
import pytest

import drpt.render.integrators.bdpt as bdpt
import drpt.render.integrators.ptracer as ptracer
from drpt.render.scene import DeviceScene
from support.mis import FAR, floor_means, spawned_segment

SEEDS = 8
#: the largest |t| of the mean relative difference (as tests/render/integrators/test_path_mis.py's)
T_MAX = 5.0
#: the largest relative difference far / origin - 1 allowed: a fortieth of the spawned hits' bias
MARGIN = 0.0005
#: standard errors of the paired differences between their mean and :data:`MARGIN`
T_SPARE = 3.5


def _difference(integrator: str) -> tuple[float, float]:
    """The mean of far / origin - 1 over the seeds, and its standard error."""
    near = floor_means(0.0, integrator, SEEDS)
    assert near.mean() > 0.005
    d = floor_means(FAR, integrator, SEEDS) / near - 1
    return float(d.mean()), float(d.std(ddof=1) / np.sqrt(len(d)))


@pytest.mark.slow
@pytest.mark.parametrize("integrator", ["ptracer", "bdpt"])
def test_a_far_scene_renders_like_the_scene_at_the_origin(monkeypatch, integrator):
    mean, se = _difference(integrator)
    assert abs(mean) < T_MAX * se and abs(mean) + T_SPARE * se < MARGIN, (mean, se)
    with monkeypatch.context() as m:
        m.setattr(DeviceScene, "intersect_from", lambda self, o, p, d, active: self.intersect(o, d, active))
        mean, se = _difference(integrator)
        assert mean < -MARGIN and mean / se < -T_MAX, (mean, se)
    for module in (ptracer, bdpt):
        monkeypatch.setattr(module, "camera_segment", spawned_segment)
    mean, se = _difference(integrator)
    assert mean / se > T_MAX, (mean, se)
