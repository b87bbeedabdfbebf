"""The worked example "Adding an emitter" of docs/architecture.md runs as written: its module
(the first code block) is loaded as ``drpt.render.lights.sun_disk`` and registered with the
builder line (the second block) in ``EMITTER_FAMILIES``, and then

* its directions follow its density (``drpt.testing.run_chi2``, significance 1%; 100,000
  samples and 32 integration points per bin side, for the cone's sharp edge), and
  ``pdf_direction`` is 0 for rays that hit something;
* the light selection counts it (one slot, beside a point light) and ``sample_emitter`` /
  ``pdf_emitter`` return its samples and densities through the scene;
* a diffuse plane (albedo 0.5) facing a sun of radiance 8 and half-angle 12 degrees renders
  ``rho L sin^2(angle)`` everywhere (the image mean within 4 standard errors, next-event
  estimation and the BSDF samples that reach the sun combined by MIS).

Negative control: the example with a density 1.3x too high (in ``bind``) renders a mean
more than 8 standard errors off."""

from __future__ import annotations

import importlib.util
import math
import re
import sys
from types import SimpleNamespace

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array2f, Array3f, Bool, Float, UInt32

from drpt.render import scene as scene_mod
from drpt.testing import run_chi2

NAME = "drpt.render.lights.sun_disk"
RHO, L, ANGLE = 0.5, 8.0, 12.0
SCENE = """PerspectiveCamera { center 0 3 3 direction 0 -1 -1 up 0 1 0 angle 30 }
Materials { numMaterials 1 Material { diffuseColor %g %g %g } }
Group { numObjects 2 MaterialIndex 0
    Triangle { vertex0 -50 0 -50 vertex1 -50 0 50 vertex2 50 0 50 }
    Triangle { vertex0 -50 0 -50 vertex1 50 0 50 vertex2 50 0 -50 }
}
""" % (RHO, RHO, RHO)


@pytest.fixture(scope="module")
def section(repo) -> str:
    return (repo / "docs" / "architecture.md").read_text().split("## Adding an emitter", 1)[1].split("\n## ", 1)[0]


@pytest.fixture
def sun_disk(tmp_path, monkeypatch, section):
    """The doc's module, registered the way the doc's second block says."""
    module_src, builder_src = re.findall(r"```python\n(.*?)```", section, re.S)[:2]
    assert module_src.startswith("# drpt/render/lights/sun_disk.py")
    path = tmp_path / "sun_disk.py"
    path.write_text(module_src)
    spec = importlib.util.spec_from_file_location(NAME, path)
    mod = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, NAME, mod)
    spec.loader.exec_module(mod)
    families = eval(builder_src.split("=", 1)[1], {"sun_disk": mod})
    monkeypatch.setattr(scene_mod, "EMITTER_FAMILIES", families)
    return mod


def _scene(tmp_path, mod, point=False):
    from drpt.scene import load_scene
    from drpt.scene.model import PointLight

    (tmp_path / "plane.txt").write_text(SCENE)
    scene = load_scene(tmp_path / "plane.txt")
    scene.lights.append(mod.SunDisk((0.0, 1.0, 0.0), (L, L, L), ANGLE))
    if point:
        scene.lights.append(PointLight((0.0, 2.0, 0.0), (1.0, 1.0, 1.0)))
    return scene


def test_directions_follow_the_density(sun_disk):
    e = sun_disk.SunDiskEmitter(sun_disk.SunDisk((0.3, 0.8, 0.2), (1.0, 2.0, 3.0), 25.0), 1.0)
    ref = Array3f(0.0, 0.0, 0.0)
    ok, msg = run_chi2(lambda u: e.sample_direction(ref, UInt32(0), u, Bool(True)).wo,
                       lambda w: e.eval_direction(w, Bool(True))[1], sample_count=100_000, ires=32)
    assert ok, msg
    hit = SimpleNamespace(valid=Bool(True))
    assert e.pdf_direction(hit, Array3f(*e.axis), Bool(True)).numpy()[0] == 0.0


def test_the_scene_samples_it_through_the_selection(tmp_path, sun_disk):
    from drpt.options import RenderOptions
    from drpt.render.scene import DeviceScene

    ds = DeviceScene(_scene(tmp_path, sun_disk, point=True), RenderOptions(delta_lights="select"))
    sel = ds.emitter_selection
    assert [type(f).__name__ for f in sel.families] == ["DeltaLights", "SunDiskEmitter"]
    n = 4096
    rng = np.random.default_rng(0)
    u = rng.random((3, n)).astype(np.float32)
    ref = SimpleNamespace(p=dr.full(Array3f, [0.0, 0.0, 0.0], n))
    es = ds.sample_emitter(ref, Float(u[0]), Array2f(Float(u[1]), Float(u[2])), dr.full(Bool, True, n))
    sun = ~Bool(es.delta).numpy()
    assert 0 < sun.sum() < n
    cos = np.array(es.wo.numpy())[1]
    assert (cos[sun] >= math.cos(math.radians(ANGLE)) - 1e-6).all()
    escaped = SimpleNamespace(valid=dr.zeros(Bool, n), p=ref.p, t=dr.full(Float, dr.inf, n), prim=dr.zeros(UInt32, n))
    pdf = ds.pdf_emitter(escaped, es.wo, dr.full(Bool, True, n)).numpy()
    np.testing.assert_allclose(pdf[sun], es.pdf.numpy()[sun], rtol=1e-6)
    cone = 2 * math.pi * (1 - math.cos(math.radians(ANGLE)))
    np.testing.assert_allclose(es.pdf.numpy()[sun], sel.probabilities[1] / cone, rtol=1e-5)


def _render_mean(tmp_path, mod):
    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer

    res = Renderer(_scene(tmp_path, mod), RenderOptions(width=24, height=24, spp=64, seed=3, progress=False)).render()
    img = np.asarray(res.image, np.float64)
    se = math.sqrt(float(np.sum(res.variance))) / img.size
    return float(img.mean()), se


def test_a_plane_facing_the_sun_renders_the_analytic_radiance(tmp_path, sun_disk):
    expect = RHO * L * math.sin(math.radians(ANGLE)) ** 2
    mean, se = _render_mean(tmp_path, sun_disk)
    assert abs(mean - expect) < 4 * se + 1e-6, (mean, expect, se)


def test_negative_control_a_wrong_density_fails(tmp_path, sun_disk, monkeypatch):
    real = sun_disk.SunDiskEmitter.bind

    def bind(self, prob):
        real(self, prob)
        self.pdf *= 1.3
    monkeypatch.setattr(sun_disk.SunDiskEmitter, "bind", bind)
    expect = RHO * L * math.sin(math.radians(ANGLE)) ** 2
    mean, se = _render_mean(tmp_path, sun_disk)
    assert abs(mean - expect) > 8 * se, (mean, expect, se)
