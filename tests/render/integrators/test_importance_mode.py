"""Light subpaths' vertices evaluated in importance mode (``eval_bsdf(..., importance=True)``).

A rough dielectric's and a principled material's transmission scale radiance by the IOR
ratio squared; importance, carried from the lights, is not so scaled (Mitsuba's
``TransportMode::Importance``), so a light subpath's vertex evaluated toward the camera (or
toward a camera subpath's vertex) has that scaling undone (``importance_scale`` of their
modules). On a rough glass sphere and a principled sphere of specular transmission on a
diffuse floor under a small area light (``tests/data/xml/rough_glass_light_tracing.xml``,
32x32, ``max_depth`` 6, independent samples), ``ptracer`` (2048 spp) and ``bdpt`` (6144 spp)
agree with the path tracer (8192 spp): 8x8-block z-tests with drpt's per-pixel variances,
|z| < 4.5 over every block and channel and the z of the image means < 4 (test_ptracer.py's
thresholds; they read 2.95 and 1.21 for ptracer, 1.50 and 0.15 for bdpt). Negative control:
the same renders with the light vertices evaluated in radiance mode (the scale left out) fail,
|z| > 6 over the blocks or the means (11.5 and 16.7; 8.7 and 10.0: ptracer's image 16% too
bright; bdpt's MIS gives those strategies less weight). The scale itself: ``eta_i^2`` on transmission from
either side, 1 on reflection.
"""

from __future__ import annotations

from pathlib import Path

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array3f, Float

from drpt.options import PathOptions, RenderOptions
from drpt.render import material
from drpt.render.bsdf import principled, roughdielectric
from drpt.render.renderer import Renderer
from drpt.scene import load_scene
from drpt.testing import agreement

SCENE = Path(__file__).resolve().parents[2] / "data" / "xml" / "rough_glass_light_tracing.xml"


def _render(integrator, spp, seed=1):
    opts = RenderOptions(width=32, height=32, spp=spp, seed=seed, integrator=integrator, progress=False,
                         path=PathOptions(max_depth=6), variance=True, sampler="independent")
    return Renderer(load_scene(SCENE), opts).render()




@pytest.fixture(scope="module")
def path_image():
    return _render("path", 8192, seed=7)


@pytest.mark.slow
@pytest.mark.parametrize("integrator, spp", [("ptracer", 2048), ("bdpt", 6144)])
def test_light_tracers_agree_with_path_tracing_through_rough_transmission(path_image, integrator, spp):
    r = _render(integrator, spp)
    assert r.nonfinite == 0 and np.all(np.isfinite(r.image)) and r.image.mean() > 1e-2
    zb, zm = agreement(r, path_image)
    assert zb < 4.5 and zm < 4.0, (zb, zm)


@pytest.mark.slow
@pytest.mark.parametrize("integrator, spp", [("ptracer", 2048), ("bdpt", 6144)])
def test_radiance_mode_at_light_vertices_fails(path_image, monkeypatch, integrator, spp):
    value = material._value
    monkeypatch.setattr(material, "_value", lambda bsdf, p, wi, wo, importance: value(bsdf, p, wi, wo, False))
    zb, zm = agreement(_render(integrator, spp), path_image)
    assert max(zb, zm) > 6.0, (zb, zm)


@pytest.mark.parametrize("module", [roughdielectric, principled])
def test_the_scale_is_the_ior_ratio_squared_on_transmission(module):
    p = (module.RoughDielectricParams(eta=Float(1.5)) if module is roughdielectric
         else principled.PrincipledParams(eta=Float(1.5)))
    up, down, up2 = Array3f(0.3, 0.0, 0.95), Array3f(-0.2, 0.1, -0.97), Array3f(-0.3, 0.2, 0.93)
    got = [module.importance_scale(p, a, b).numpy()[0] for a, b in ((up, down), (down, up), (up, up2),
                                                                      (down, Array3f(0.1, 0.0, -0.99)))]
    np.testing.assert_allclose(got, [1.5 ** 2, 1 / 1.5 ** 2, 1.0, 1.0], rtol=1e-6)
    dr.eval()
