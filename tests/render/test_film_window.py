"""Mitsuba's hdrfilm crop window and perspective principal_point_offset (drpt.scene.model.FilmWindow,
drpt.render.camera.RayCamera): camera rays equal Mitsuba's ``sensor.sample_ray`` on cropped and
shifted films; a cropped, shifted corpus scene (tests/data/xml/crop.xml) renders like Mitsuba on the
same file (block z-test), and fails it when drpt ignores the window (negative control); a scene
without a window traces the kernel it always did (test_kernel_op_count_unchanged)."""

from __future__ import annotations

import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from drpt.scene import load_scene

XML = Path(__file__).resolve().parents[1] / "data" / "xml"  # tests/data/xml


def _camera_xml(path: Path, plugin: str, crop, ppo, W=48, H=30) -> Path:
    lens = ('<float name="aperture_radius" value="0.2"/><float name="focus_distance" value="4"/>'
            if plugin == "thinlens" else "")
    pp = (f'<float name="principal_point_offset_x" value="{ppo[0]}"/>'
          f'<float name="principal_point_offset_y" value="{ppo[1]}"/>' if ppo != (0, 0) else "")
    path.write_text(
        f'<scene version="3.0.0"><sensor type="{plugin}">{lens}{pp}<float name="fov" value="50"/>'
        '<transform name="to_world"><lookat origin="1, 2, 3" target="-1, 0.5, -2" up="0.2, 1, 0"/></transform>'
        f'<film type="hdrfilm"><integer name="width" value="{W}"/><integer name="height" value="{H}"/>'
        f'<integer name="crop_offset_x" value="{crop[0]}"/><integer name="crop_offset_y" value="{crop[1]}"/>'
        f'<integer name="crop_width" value="{crop[2]}"/><integer name="crop_height" value="{crop[3]}"/>'
        '</film></sensor></scene>')
    return path


@pytest.mark.mitsuba
@pytest.mark.parametrize("plugin,crop,ppo", [
    ("perspective", (7, 5, 20, 13), (0.05, -0.1)),
    ("perspective", (0, 0, 48, 30), (0.2, 0.1)),
    ("perspective", (7, 5, 20, 13), (0.0, 0.0)),
    ("perspective", (40, 0, 8, 30), (-0.3, 0.0)),
    ("thinlens", (30, 2, 10, 20), (0.0, 0.0)),
])
def test_rays_match_mitsubas_sample_ray(tmp_path, plugin, crop, ppo):
    import mitsuba as mi
    from drjit.auto import Array2f, Float

    from drpt.backend import mitsuba_variant
    from drpt.render.camera import RayCamera

    p = _camera_xml(tmp_path / "cam.xml", plugin, crop, ppo)
    s = load_scene(p)
    cw, ch = crop[2], crop[3]
    assert (s.settings.width, s.settings.height) == (cw, ch)  # the image is the crop window
    xs, ys = np.meshgrid(np.linspace(0, cw, 9), np.linspace(0, ch, 7))
    xs, ys = xs.ravel(), ys.ravel()
    cam = RayCamera(s.camera, cw, ch)
    lu = np.random.default_rng(1).random((2, xs.size))
    o, d = cam.ray(Float(xs), Float(ys), Array2f(lu[0], lu[1]) if cam.thin_lens else None)
    o, d = np.array(o).T, np.array(d).T
    mi.set_variant(mitsuba_variant())
    sensor = mi.load_file(str(p)).sensors()[0]
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(xs / cw, ys / ch), mi.Point2f(lu[0], lu[1]))
    md, mo = np.array(ray.d).T, np.array(ray.o).T
    assert np.abs(d - md).max() < 2e-6, np.abs(d - md).max()
    # Mitsuba's origin lies on the near plane, along the same ray
    assert np.linalg.norm(np.cross(mo - o, d), axis=1).max() < 1e-5
    # negative control: the same rays without the window are not Mitsuba's
    _, d0 = RayCamera(replace(s.camera, window=None), cw, ch).ray(Float(xs), Float(ys))
    assert np.abs(np.array(d0).T - md).max() > 1e-2


def test_window_bounds_and_refusals(tmp_path):
    from drpt.errors import SceneError

    s = load_scene(XML / "crop.xml")
    w = s.camera.window
    assert (w.film_width, w.film_height, w.offset_x, w.offset_y, w.crop_size) == (64, 48, 20, 10, (32, 24))
    assert np.allclose(w.bounds(), (20 / 64 + 0.06, 10 / 48 - 0.04, 52 / 64 + 0.06, 34 / 48 - 0.04))
    assert (s.settings.width, s.settings.height) == (32, 24)
    p = _camera_xml(tmp_path / "bad.xml", "perspective", (40, 0, 10, 30), (0, 0))
    with pytest.raises(SceneError, match="crop window"):
        load_scene(p)
    # Mitsuba's thinlens reads no principal point offset: an unread parameter, like Mitsuba
    p = _camera_xml(tmp_path / "tl.xml", "thinlens", (0, 0, 48, 30), (0.1, 0.0))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        s = load_scene(p)
    assert s.camera.window is None
    assert any("principal_point_offset_x" in str(m.message) for m in caught)


@pytest.mark.mitsuba
def test_export_of_a_cropped_camera_is_mitsubas_film(tmp_path):
    import mitsuba as mi

    from drpt.backend import mitsuba_variant
    from drpt.export.mitsuba import to_mitsuba_dict

    s = load_scene(XML / "crop.xml")
    d = to_mitsuba_dict(s, 32, 24, 4)
    f = d["sensor"]["film"]
    assert (f["width"], f["height"], f["crop_offset_x"], f["crop_offset_y"], f["crop_width"], f["crop_height"]) \
        == (64, 48, 20, 10, 32, 24)
    assert (d["sensor"]["principal_point_offset_x"], d["sensor"]["principal_point_offset_y"]) == (0.06, -0.04)
    mi.set_variant(mitsuba_variant())
    a = mi.load_dict(d).sensors()[0]
    b = mi.load_file(str(XML / "crop.xml")).sensors()[0]
    u = mi.Point2f(np.linspace(0, 1, 5), np.linspace(1, 0, 5))
    assert np.allclose(np.array(a.sample_ray(0, 0.5, u, u)[0].d), np.array(b.sample_ray(0, 0.5, u, u)[0].d),
                       atol=1e-6)
    from drpt.errors import DrptError

    with pytest.raises(DrptError, match="film window"):
        to_mitsuba_dict(s, 64, 48, 4)


@pytest.mark.slow
@pytest.mark.mitsuba
def test_cropped_scene_renders_like_mitsuba():
    from drpt.testing import assert_agree, block_z
    from support.xml import render_xml_both

    scene = load_scene(XML / "crop.xml")
    r, ref, var = render_xml_both(scene, XML / "crop.xml", 256)
    assert r.image.shape == (24, 32, 3) and ref.shape == (24, 32, 3)
    assert_agree(r, ref, var, zmax=4.5)
    # negative control: the centered whole film at the crop's size is not that image
    scene.camera = replace(scene.camera, window=None)
    r0, _, _ = render_xml_both(scene, XML / "crop.xml", 256)
    z = block_z(r0.image, r0.variance, ref, var)
    assert np.abs(z).max() > 6.0


@pytest.mark.parametrize("sampler, count", [("independent", 4395), ("auto", 4568)])
def test_kernel_op_count_unchanged_without_a_window(sampler, count):
    """A camera without a window traces the same kernel as without window support (the
    Cornell box path kernel with ``--sampler independent``: 4395 operations, the count of
    the kernel with one next-event sample per vertex through ``DeviceScene.sample_emitter``
    and hashed PCG32 streams, its ceiling light's two triangles tested as one parallelogram
    by the inline accelerator (:mod:`drpt.geometry.parallelogram`: 194 fewer than two
    triangle tests), each lane's pixel and sample found by a float64 reciprocal instead
    of opaque integer divisions (``drpt.render.lanes``: five operations more, no scalarized
    vector division), and a loop state that carries the path's last vertex for the MIS
    density of the emitter a BSDF-sampled ray hits (``PathState.ref_p``: the area density's
    distance seen from the point next-event estimation sampled from), a hit's triangle
    read from its packed record by two packet gathers (``SurfaceData.tri_fields``), and the
    small per-material, per-primitive and emitter tables, and the ceiling light's two triangle
    records, read as compares and selects of literals instead of gathers (``drpt.render.tables``:
    more operations, less time), its four lanes a pixel of one sample each (at 32x32 and 4 spp
    path regeneration gives a lane per sample: the bounce loop without the code that starts a
    lane's next path, ``PathIntegrator._loop_single``, its vertices in a symbolic ``if`` on their
    live lanes, ``PathIntegrator.loop_branched``; Russian roulette below a throughput before
    ``rr_depth``, ``PathOptions.rr_threshold``: six operations) summing the
    samples and their squares (``film.lane_sums`` adds a pixel's lanes in a kernel of its own), and the
    pass's dropped non-finite samples added in the kernel (``film.dropped_total``: a masked
    atomic addition, ten operations, where a per-lane array was written); with
    the default ``auto``, which is ``ldsampler`` for the path integrator: 4568, the same kernel drawing
    from Owen-scrambled Sobol sequences; a change to either kernel updates its count here)."""
    import drjit as dr

    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer

    cornell = Path(__file__).resolve().parents[2] / "scenes" / "cornellbox" / "cornellbox.txt"
    s = load_scene(cornell)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        r = Renderer(s, RenderOptions(width=32, height=32, spp=4, bsdf="phong", sampler=sampler,
                                      progress=False))
        dr.kernel_history_clear()
        r.render()
        h = dr.kernel_history()
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    ops = sorted(k.get("operation_count", 0) for k in h if k.get("type") == dr.KernelType.JIT)
    assert ops[-1] == count, ops[-3:]
