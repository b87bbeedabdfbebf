"""The thin-lens camera (depth of field): scene-format fields, ray geometry,
Mitsuba ``thinlens`` equivalence ray by ray and in renders, export, viewer."""

from __future__ import annotations

import math
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from drpt.errors import DrptError, SceneError
from drpt.scene import PerspectiveCamera, load_scene

CAM = "PerspectiveCamera {{ center 0 0 5 direction 0 0 -1 up 0 1 0 angle 45{extra} }}\n"


def _load(tmp_path, extra: str):
    p = tmp_path / "lens.txt"
    p.write_text(CAM.format(extra=extra))
    return p, load_scene(p)


# ------------------------------------------------------------ scene format
def test_lens_fields_parse(tmp_path):
    _, s = _load(tmp_path, "\n apertureRadius 0.25\n focusDistance 4.5")
    cam = s.camera
    assert isinstance(cam, PerspectiveCamera)
    assert (cam.aperture_radius, cam.focus_distance, cam.fov) == (0.25, 4.5, 45.0)
    _, s = _load(tmp_path, " focusDistance 3 apertureRadius 0.1")  # any order
    assert (s.camera.aperture_radius, s.camera.focus_distance) == (0.1, 3.0)
    _, s = _load(tmp_path, "")
    assert (s.camera.aperture_radius, s.camera.focus_distance) == (0.0, None)  # a pinhole
    with pytest.warns(UserWarning, match="focusDistance has no effect"):
        _, s = _load(tmp_path, " apertureRadius 0 focusDistance 2")  # aperture 0: a pinhole too
    assert s.camera.aperture_radius == 0.0


def test_focus_distance_without_aperture_warns_at_its_line(tmp_path):
    p = tmp_path / "lens.txt"
    p.write_text(CAM.format(extra="\n\n focusDistance 2"))
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        load_scene(p)
    msgs = [str(x.message) for x in w]
    assert any(m.startswith(f"{p.resolve()}:3: focusDistance has no effect") for m in msgs), msgs


@pytest.mark.parametrize("extra, line, fragment", [
    ("\n apertureRadius -0.1 focusDistance 2", 2, "apertureRadius must be between 0 and"),
    ("\n apertureRadius 0.1", 2, "apertureRadius needs focusDistance"),
    (" apertureRadius 0.1\n\n focusDistance 0", 3, "focusDistance must be positive"),
    (" apertureRadius 0.1\n focusDistance -4", 2, "focusDistance must be positive"),
    (" apertureRadius 0.1 focusDistance 1e13", 1, "focusDistance must be positive and at most"),
    ("\n apertureRadius 0.1 apertureRadius 0.2 focusDistance 1", 2, "'apertureRadius' given twice"),
    ("\n apertureRadius wide focusDistance 1", 2, "apertureRadius"),
    ("\n focusDistance", 2, "expected a finite number for focusDistance"),
    ("\n apertureradius 0.1", 2, "did you mean 'apertureRadius'"),
])
def test_lens_errors_are_one_line_with_file_and_line(tmp_path, extra, line, fragment):
    p = tmp_path / "lens.txt"
    p.write_text(CAM.format(extra=extra))
    with pytest.raises(SceneError) as e:
        load_scene(p)
    msg = str(e.value)
    assert msg.startswith(f"{p.resolve()}:{line}: "), msg
    assert fragment in msg and "\n" not in msg, msg


def test_orthographic_camera_has_no_lens(tmp_path):
    p = tmp_path / "o.txt"
    p.write_text("OrthographicCamera { center 0 0 5 direction 0 0 -1 up 0 1 0 size 2\n"
                 "  apertureRadius 0.1 focusDistance 2 }\n")
    with pytest.raises(SceneError, match=r"o.txt:2: unknown field in OrthographicCamera "
                                         r"'apertureRadius'"):
        load_scene(p)


def test_camera_block_keeps_the_lens(tmp_path):
    from drpt.view.pose import camera_block, camera_to_pose, pose_to_camera

    cam = PerspectiveCamera((0.5, 1.0, 4.0), (0.1, -0.2, -1.0), (0.0, 1.0, 0.0), 35.0, 0.125, 3.5)
    (tmp_path / "s.txt").write_text(camera_block(cam) + "Group { numObjects 0 }\n")
    assert load_scene(tmp_path / "s.txt").camera == cam
    pos, wxyz, fov = camera_to_pose(cam)
    back = pose_to_camera(pos, wxyz, fov, cam)
    assert (back.aperture_radius, back.focus_distance) == (0.125, 3.5)
    assert math.isclose(back.fov, 35.0)


# ------------------------------------------------------------ ray geometry
W, H = 64, 48
LENS = PerspectiveCamera((1.0, 2.0, 3.0), (0.3, -0.2, -1.0), (0.0, 1.0, 0.0), 50.0, 0.3, 4.0)


def _rays(cam, x, y, u):
    """drpt's rays through pixel positions (x, y) (scalars or arrays) and lens samples u."""
    from drjit.auto import Array2f, Float

    from drpt.render.camera import RayCamera

    n = len(u)
    x, y = (np.broadcast_to(np.asarray(v, np.float64), (n,)) for v in (x, y))
    o, d = RayCamera(cam, W, H).ray(Float(x), Float(y), Array2f(u[:, 0], u[:, 1]))
    return np.array(o).T.astype(np.float64), np.array(d).T.astype(np.float64)


def test_thin_lens_rays_meet_on_the_focal_plane():
    from drpt.render.camera import camera_basis

    f, r, u = camera_basis(LENS)
    rng = np.random.default_rng(1)
    uv = rng.random((4096, 2))
    c = np.asarray(LENS.center)
    for x, y in ((32.0, 24.0), (3.5, 40.25), (63.0, 0.5)):
        o, d = _rays(LENS, x, y, uv)
        assert np.allclose(np.linalg.norm(d, axis=1), 1, atol=1e-6)
        # origins: on the lens disk, perpendicular to f, uniform (E|o - c|^2 = A^2 / 2)
        rel = o - c
        assert np.abs(rel @ f).max() < 1e-6
        rad = np.linalg.norm(rel, axis=1)
        assert rad.max() <= LENS.aperture_radius * (1 + 1e-6)
        assert abs(np.mean(rad**2) - LENS.aperture_radius**2 / 2) < 0.03 * LENS.aperture_radius**2
        assert np.linalg.norm(rel.mean(0)) < 0.02 * LENS.aperture_radius
        # every ray passes the pinhole ray's point at distance F along f
        pin_o, pin_d = _rays(replace(LENS, aperture_radius=0.0), x, y, uv[:1])
        p = pin_o[0] + pin_d[0] * (LENS.focus_distance / (pin_d[0] @ f))
        t = ((p - o) @ f) / (d @ f)
        assert np.abs(o + d * t[:, None] - p).max() < 1e-5 * LENS.focus_distance
    # the same camera without an aperture is the pinhole camera, ray for ray
    o, d = _rays(replace(LENS, aperture_radius=0.0), 10.0, 20.0, uv[:8])
    assert np.allclose(o, c) and np.allclose(d, d[0])


def test_thin_lens_needs_a_focus_distance():
    from drpt.render.camera import RayCamera

    with pytest.raises(DrptError, match="positive focus distance"):
        RayCamera(replace(LENS, focus_distance=None), W, H)


def test_changing_the_lens_compiles_nothing(tmp_path):
    import drjit as dr

    from drpt.options import PathOptions, RenderOptions
    from drpt.render.renderer import Renderer

    p = tmp_path / "s.txt"
    p.write_text(CAM.format(extra=" apertureRadius 0.2 focusDistance 3")
                 + "Background { color 0.5 0.5 0.5 }\n"
                 + "Group { numObjects 1 Sphere { center 0 0 0 radius 1 } }\n")
    scene = load_scene(p)
    opts = RenderOptions(width=8, height=8, spp=2, progress=False, path=PathOptions(max_depth=2))
    r = Renderer(scene, opts)
    r.render()
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        dr.kernel_history()  # clear
        images = [r.derive(opts, replace(scene.camera, aperture_radius=a, focus_distance=fd)).render().image
                  for a, fd in ((0.05, 2.0), (0.4, 6.0))]
        hist = dr.kernel_history([dr.KernelType.JIT])
    assert hist and all(k["cache_hit"] for k in hist), [k["cache_hit"] for k in hist]
    assert not np.array_equal(images[0], images[1])


# ------------------------------------------------------------ against Mitsuba
@pytest.fixture(scope="module")
def mi():
    mi = pytest.importorskip("mitsuba")
    from drpt.backend import mitsuba_variant

    mi.set_variant(mitsuba_variant())
    return mi


def _scene(cam):
    from drpt.scene.model import Material, Scene

    return Scene(path=Path("lens.txt"), camera=cam, materials=[Material("m")])


@pytest.mark.mitsuba
def test_rays_equal_mitsubas_thinlens(mi):
    """Mitsuba's thinlens ``sample_ray`` (exported camera) and drpt's camera
    give the same ray for the same film position and lens sample: the same
    direction, and Mitsuba's origin (moved to its near clip plane) on drpt's ray."""
    from drpt.export.mitsuba import to_mitsuba_dict

    d = to_mitsuba_dict(_scene(LENS), W, H, 1)
    assert d["sensor"]["type"] == "thinlens"
    assert (d["sensor"]["aperture_radius"], d["sensor"]["focus_distance"]) == (0.3, 4.0)
    sensor = mi.load_dict(d["sensor"])
    rng = np.random.default_rng(7)
    pos, ap = rng.random((2000, 2)), rng.random((2000, 2))
    ray, weight = sensor.sample_ray(0.0, 0.5, mi.Point2f(pos[:, 0], pos[:, 1]),
                                    mi.Point2f(ap[:, 0], ap[:, 1]))
    assert np.allclose(np.array(weight), 1.0)
    mo, md = np.array(ray.o).T, np.array(ray.d).T
    o, dd = _rays(LENS, pos[:, 0] * W, pos[:, 1] * H, ap)
    assert np.abs(md - dd).max() < 2e-5
    off = mo - o
    assert np.abs(np.cross(off, dd)).max() < 1e-5  # mo = o + t d (t: the near clip)


@pytest.mark.mitsuba
def test_xml_export_loads_as_thinlens(mi, tmp_path):
    from drpt.export.mitsuba import write_xml

    xml = write_xml(_scene(LENS), tmp_path / "s.xml", W, H, 4, rfilter="gaussian:stddev=0.3")
    text = xml.read_text()
    assert '<sensor type="thinlens"' in text and 'name="aperture_radius" value="0.3"' in text
    s = mi.load_file(str(xml))
    sensor = s.sensors()[0]
    assert sensor.class_name() == "ThinLensCamera"
    params = mi.traverse(sensor)
    for key, value in (("aperture_radius", 0.3), ("focus_distance", 4.0)):
        assert math.isclose(np.asarray(params[key]).ravel()[0], value, rel_tol=1e-6)
    assert "stddev=0.30" in str(sensor.film().rfilter())


EDGE_SPP = 256


@pytest.fixture(scope="module")
def dof(mi, tmp_path_factory):
    """The edge scene with spheres through a thin lens focused at 3, and
    Mitsuba's batches of it (box filter)."""
    from drpt.testing import mitsuba_runs
    from support.scenes import edge_scene

    d = tmp_path_factory.mktemp("dof")

    def load(aperture):
        p = d / f"s{len(list(d.iterdir()))}.txt"
        p.write_text(edge_scene(aperture, spheres=True))
        return load_scene(p)

    runs = mitsuba_runs(load((0.15, 3.0)), 48, 48, 512, max_depth=2, seed=5)
    return load, runs


def _z(scene, runs):
    from drpt.options import PathOptions, RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.testing import block_z_correlated

    r = Renderer(scene, RenderOptions(width=48, height=48, spp=EDGE_SPP, seed=1, progress=False,
                                      path=PathOptions(max_depth=2))).render()
    assert np.all(np.isfinite(r.image)) and r.nonfinite == 0
    return float(np.abs(block_z_correlated(r.image, r.variance, runs, block=4)[0]).max())


@pytest.mark.slow
@pytest.mark.mitsuba
def test_depth_of_field_agrees_with_mitsuba(dof):
    load, runs = dof
    assert _z(load((0.15, 3.0)), runs) < 4.5


@pytest.mark.slow
@pytest.mark.mitsuba
def test_wrong_lens_fails_the_z_test(dof):
    """Negative controls: a pinhole, a focus 10% too far, an aperture 13%
    too small, against Mitsuba's thin lens (aperture 0.15, focus 3)."""
    load, runs = dof
    assert _z(load(None), runs) > 20
    assert _z(load((0.15, 3.3)), runs) > 4.5
    assert _z(load((0.13, 3.0)), runs) > 4.5
