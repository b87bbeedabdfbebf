"""Light tracing (drpt/render/integrators/ptracer.py) and its splatting film (drpt/render/film.py).

Statistics: 8x8-block z-tests (``drpt.testing.block_z``) of the light-traced image
against the path-traced one (same scene, drpt's per-pixel variances) or against Mitsuba's ``path``
on the same XML file (variance from 8 seeds), threshold |z| < 4.5 over every block and channel,
and the z of the image means < 4. Negative controls: the camera's importance without its
``1 / cos^3`` and a light tracer that hides what the camera sees of emitters must fail the same
test.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array3f, Bool, Float

import drpt.render.integrators.bdpt as bdpt
import drpt.render.integrators.ptracer as ptracer
from drpt.errors import DrptError
from drpt.filters import PixelFilter
from drpt.options import PathOptions, RenderOptions
from drpt.render.film import SplatFilm
from drpt.render.renderer import Renderer
from drpt.render.scene import DeviceScene
from drpt.scene import load_scene
from drpt.testing import agreement

REPO = Path(__file__).resolve().parents[3]
XML = REPO / "tests" / "data" / "xml"


# ------------------------------------------------------------ the film
def test_box_film_adds_to_the_containing_pixel():
    film = SplatFilm(4, 3, PixelFilter())
    film.put(Float(2.3, 0.0, 3.99, 4.0), Float(1.7, 0.0, 2.5, 0.5),
             Array3f(Float(1.0, 10.0, 100.0, 1000.0), 2.0, 3.0), Bool(True))
    s, q, w = film.arrays()
    assert w is None
    assert s[1, 2].tolist() == [1.0, 2.0, 3.0] and q[1, 2].tolist() == [1.0, 4.0, 9.0]
    assert s[0, 0, 0] == 10.0 and s[2, 3, 0] == 100.0
    assert s.sum(axis=(0, 1))[0] == 111.0  # x = 4.0 lies outside the image: dropped


@pytest.mark.parametrize("flt", [PixelFilter("tent", 1.0), PixelFilter("tent", 1.7),
                                 PixelFilter("gaussian", 0.5)])
def test_filtered_film_weights_match_the_filter_and_sum_to_one(flt):
    W = H = 9
    film = SplatFilm(W, H, flt)
    x, y = 4.3, 4.8
    film.put(Float(x), Float(y), Array3f(1.0, 1.0, 1.0), Bool(True))
    s, _, _ = film.arrays()
    assert abs(s[..., 0].sum() - 1.0) < 1e-5
    cx, cy = np.arange(W) + 0.5 - x, np.arange(H) + 0.5 - y
    w = flt.eval(cy)[:, None] * flt.eval(cx)[None, :]
    assert np.allclose(s[..., 0], w / w.sum(), atol=1e-6)
    # a camera film (weights): unnormalized w L, w^2 L^2, w, w^2, over rows 2..7 only
    film = SplatFilm(W, H, flt, weights=True, y0=2, rows=6)
    film.put(Float(x), Float(y), Array3f(2.0, 2.0, 2.0), Bool(True))
    s, q, ws = film.arrays()
    w = w[2:8]
    assert np.allclose(s[..., 0], 2 * w, atol=1e-6) and np.allclose(q[..., 0], 4 * w * w, atol=1e-6)
    assert np.allclose(ws[..., 0], w, atol=1e-6) and np.allclose(ws[..., 1], w * w, atol=1e-6)


@pytest.mark.parametrize("flt", [PixelFilter("tent", 1.0), PixelFilter("gaussian", 0.5),
                                 PixelFilter("gaussian", 0.9)])
def test_gathered_splats_equal_the_scattered_ones(flt):
    """gather_splats (each pixel gathers its neighbours' samples) sums what SplatFilm
    scatters, for a band of rows 3..8 of a 12x10 image with 5 samples per pixel; a
    negative control: the band's samples attributed one row off do not."""
    import drjit as dr
    from drjit.auto import PCG32, UInt32

    from drpt.render.film import gather_splats

    W, H, r0, rows, k = 12, 10, 3, 5, 5
    n = W * rows * k
    rng = PCG32(n, initstate=7)
    pix = dr.arange(UInt32, n) // k
    x = Float(pix % W) + rng.next_float32()
    y = Float(pix // W + r0) + rng.next_float32()
    L = Array3f(rng.next_float32(), rng.next_float32() * 2.0, 1.0)
    ok = rng.next_float32() < 0.9
    y0, s, q, w = gather_splats(flt, W, H, r0, rows, k, x, y, L, ok, moment=True)
    film = SplatFilm(W, H, flt, weights=True, moment=True)
    film.put(x, y, L, ok)
    fs, fq, fw = film.arrays()
    assert y0 == max(0, r0 - (int(np.ceil(flt.radius + 0.5)) - 1))
    hi = y0 + s.shape[0]
    for a, b in ((s, fs), (q, fq), (w, fw)):
        assert np.allclose(a, b[y0:hi], rtol=1e-5, atol=1e-7)
        assert not b[:y0].any() and not b[hi:].any()
    _, s1, _, _ = gather_splats(flt, W, H, r0 + 1, rows, k, x, y, L, ok)
    assert not np.allclose(s1[:s.shape[0] - 1], s[1:], rtol=1e-3)


# ------------------------------------------------------------ the estimator
def _render(scene, integrator, spp, seed=1, **kw):
    opts = RenderOptions(width=32, height=32, spp=spp, seed=seed, integrator=integrator, progress=False,
                         path=PathOptions(max_depth=4, **kw), variance=True)
    return Renderer(scene, opts)




@pytest.fixture(scope="module")
def cornell():
    return load_scene(REPO / "scenes" / "cornellbox" / "cornellbox.txt")


@pytest.fixture(scope="module")
def cornell_path(cornell):
    return _render(cornell, "path", 512).render()


@pytest.mark.slow
def test_light_tracing_agrees_with_path_tracing_on_the_cornell_box(cornell, cornell_path):
    r = _render(cornell, "ptracer", 256).render()
    assert r.nonfinite == 0 and np.all(np.isfinite(r.image))
    zb, zm = agreement(r, cornell_path)
    assert zb < 4.5 and zm < 4.0, (zb, zm)


@pytest.mark.slow
@pytest.mark.parametrize("what", ["no cos^3 in the importance", "emitters hidden from the camera"])
def test_negative_controls_fail(cornell, cornell_path, what):
    renderer = _render(cornell, "ptracer", 256)
    if what == "no cos^3 in the importance":
        cam = renderer.camera
        connect = cam.connect

        def flat(p):
            x, y, wc, dist, imp, valid = connect(p)
            cos_t = dr.dot(-wc, cam.f)
            return x, y, wc, dist, imp * cos_t * cos_t * cos_t, valid

        cam.connect = flat
    else:
        renderer = renderer.derive(replace(renderer.opt, path=replace(renderer.opt.path, hide_emitters=True)))
    zb, _ = agreement(renderer.render(), cornell_path)
    assert zb > 6.0, zb


@pytest.mark.slow
def test_light_tracing_variance_estimate_is_calibrated(cornell):
    """Two light-traced renders of different seeds differ by their estimated variances:
    the per-pixel z has a standard deviation near 1 (0.9-1.1 with 3072 pixel channels)."""
    a = _render(cornell, "ptracer", 64, seed=1).render()
    b = _render(cornell, "ptracer", 64, seed=2).render()
    z = (a.image - b.image) / np.sqrt(a.variance + b.variance + 1e-12)
    assert 0.9 < z.std() < 1.1, z.std()


@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("name", ["ptracer", "projector_spot", "area_textured", "sphere_light"])
def test_light_tracing_of_an_xml_scene_agrees_with_mitsubas_path(name):
    """drpt's light tracer against Mitsuba's camera integrator on the same file:
    tests/data/xml/ptracer.xml (an area light, point, spot and directional lights and an
    environment map; the file's integrator is ptracer, Mitsuba renders it with path),
    projector_spot.xml (a textured projector and a textured spot; Mitsuba's direct),
    area_textured.xml (an area light with a bitmap radiance; Mitsuba's path) and
    sphere_light.xml (analytic sphere lights, where light paths start and which the camera
    sees, and a rectangle light; Mitsuba's path)."""
    from support.xml import render_xml_both

    path = XML / f"{name}.xml"
    scene = load_scene(path, defines={"spp": "512"})
    defines = {"integrator": "path"} if name == "ptracer" else {}
    r, ref, var = render_xml_both(scene, path, 512, defines, integrator="ptracer")

    class Ref:
        image, variance = ref, var

    zb, zm = agreement(r, Ref)
    assert zb < 4.5 and zm < 4.0, (zb, zm)


# ------------------------------------------------------------ what it refuses
def test_light_tracing_refuses_what_it_cannot_render(cornell, tmp_path):
    lens = replace(cornell, camera=replace(cornell.camera, aperture_radius=0.1, focus_distance=3.0))
    with pytest.raises(DrptError, match="pinhole"):
        _render(lens, "ptracer", 1)
    xml = tmp_path / "glass.xml"  # (rough glass it renders; an orthographic camera it refuses)
    xml.write_text("""<scene version="3.0.0"><integrator type="ptracer"/>
        <sensor type="orthographic"><film type="hdrfilm"><integer name="width" value="8"/>
        <integer name="height" value="8"/></film></sensor>
        <shape type="sphere"><bsdf type="roughdielectric"/></shape>
        <emitter type="point"><point name="position" x="0" y="0" z="3"/></emitter></scene>""")
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-m", "drpt", "render", str(xml), "-o", str(tmp_path / "g.exr"), "-q"],
                       capture_output=True, text=True, cwd=REPO)
    assert r.returncode == 2 and "pinhole" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "g.exr").exists()


# ------------------------------------------------------------ chunks and resumed renders
@pytest.mark.parametrize("what", ["gaussian splatting", "light tracing"])
def test_splatted_renders_are_the_same_in_chunks_and_resumed(cornell, tmp_path, what):
    """A splatting film's sums (and weights) add across chunks and a checkpoint: a render
    interrupted after 3 of 8 chunks and resumed gives the plain render's image bit for bit
    (light tracing: its variance to 1e-12, the film's float64 atomic sums vary in their last bits)."""
    from support.resume import interrupted_then_resumed

    kw = {"filter": "gaussian"} if what == "gaussian splatting" else {"integrator": "ptracer"}
    opts = RenderOptions(width=16, height=12, spp=8, chunk_spp=1, seed=4, progress=False,
                         max_lanes=96, variance=True, **kw)
    plain = Renderer(cornell, opts).render()
    resumed = interrupted_then_resumed(cornell, opts, tmp_path / "cut.exr").result
    assert np.array_equal(resumed.image, plain.image)
    if what == "gaussian splatting":  # gathered sums: the same order every time
        assert np.array_equal(resumed.variance, plain.variance)
    else:
        assert np.allclose(resumed.variance, plain.variance, rtol=1e-12, atol=0)


def test_light_tracing_without_emitters_is_black_and_refuses_emissive_planes(tmp_path):
    from drpt.options import with_scene_settings

    body = """<scene version="3.0.0"><integrator type="ptracer"/>
        <sensor type="perspective"><transform name="to_world"><lookat origin="0,0,4" target="0,0,0"
        up="0,1,0"/></transform><film type="hdrfilm"><integer name="width" value="8"/>
        <integer name="height" value="8"/><rfilter type="box"/></film></sensor>
        <shape type="sphere"><bsdf type="diffuse"/></shape></scene>"""
    dark = tmp_path / "dark.xml"
    dark.write_text(body)
    scene = load_scene(dark)
    r = Renderer(scene, replace(with_scene_settings(RenderOptions(progress=False), scene)[0], spp=4)).render()
    assert r.nonfinite == 0 and not r.image.any()
    lit = tmp_path / "plane.txt"
    lit.write_text("""PerspectiveCamera { center 0 0 5 direction 0 0 -1 up 0 1 0 angle 40 }
Materials { numMaterials 1
  Material { diffuseColor 0 0 0 Ke 1 1 1 }
}
Group { numObjects 1
  MaterialIndex 0
  Plane { normal 0 0 1 offset -1 }
}
""")
    with pytest.raises(DrptError, match="emissive planes"):
        _render(load_scene(lit), "ptracer", 4)


def test_a_point_light_with_attenuation_is_refused_at_its_line(tmp_path):
    from drpt.errors import Loc, SceneError

    p = tmp_path / "att.txt"
    p.write_text("""PerspectiveCamera { center 0 0 5 direction 0 0 -1 up 0 1 0 angle 40 }
Lights { numLights 1
  PointLight { position 0 2 2 color 1 1 1 attenuation 1 0 0 }
}
Group { numObjects 1
  Sphere { center 0 0 0 radius 1 }
}
""")
    with pytest.raises(SceneError, match="physical point lights") as e:
        _render(load_scene(p), "ptracer", 4)
    assert e.value.loc == Loc(p.resolve(), 3)


@pytest.mark.parametrize("integrator", ["ptracer", "bdpt"])
def test_a_camera_segment_too_grazing_to_test_adds_nothing(cornell, monkeypatch, integrator):
    """A camera connection whose shadow segment is empty (``camera_segment``'s ``tmax <= 0``:
    too grazing to test) is dropped, not splatted untested: with every segment empty, the
    Cornell box renders as with every camera connection occluded (light tracing: black; bdpt:
    bit-identical). Negative control: with the segments' ``tmax`` kept, the images differ
    (the splats are there to drop)."""
    module = ptracer if integrator == "ptracer" else bdpt
    segment = module.camera_segment

    def render():
        opts = RenderOptions(width=16, height=16, spp=4, seed=1, progress=False, integrator=integrator,
                             sampler="independent")
        return Renderer(cornell, opts).render().image

    plain = render()
    with monkeypatch.context() as m:
        m.setattr(module, "camera_segment", lambda *a: (*segment(*a)[:2], Float(-1.0)))
        empty = render()
    with monkeypatch.context() as m:
        if integrator == "ptracer":
            m.setattr(DeviceScene, "occluded", lambda self, o, d, tmax, active, coherent=False: Bool(active))
        else:
            m.setattr(bdpt.BDPTIntegrator, "_camera_occluded", lambda self, o, d, tmax, active: Bool(active))
        hidden = render()
    assert np.array_equal(empty, hidden)
    if integrator == "ptracer":
        assert not np.any(empty)
    assert not np.array_equal(plain, hidden)  # control
