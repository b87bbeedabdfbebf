"""The unrolled short path (drpt/render/integrators/path.py): the vertex branch makes the
vertex's PCG32 draws and, without emissive surfaces, the hit's interaction on its live lanes
(``PathIntegrator.deferred``), and camera rays query the accelerator only where they reach a
shape's box (``PathIntegrator.cull``); the images are those without either, bit for bit."""

import drjit as dr
import numpy as np
import pytest

from drpt.accel import embree_lib
from drpt.accel.boxes import ShapeBoxes
from drpt.options import PathOptions, RenderOptions
from drpt.render.integrators import path
from drpt.render.integrators.path import PathIntegrator
from drpt.render.renderer import Renderer
from drpt.scene import load_scene

#: a small sphere over a floor lit by a directional light: most camera rays escape (nothing to
#: see there), the hits shade with next-event estimation; no emissive surface
FLOATING_XML = """<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="{depth}"/></integrator>
  <sensor type="perspective">
    <transform name="to_world"><lookat origin="0, -4, 3" target="0, 0, 0.3" up="0, 0, 1"/></transform>
    <film type="hdrfilm"><integer name="width" value="24"/><integer name="height" value="16"/>
      <rfilter type="box"/></film>
  </sensor>
  <emitter type="directional"><vector name="direction" value="0.3, 0, -1"/>
    <rgb name="irradiance" value="1"/></emitter>
  <shape type="sphere"><point name="center" x="0" y="0" z="1"/><float name="radius" value="0.6"/>
    <bsdf type="diffuse"/></shape>
  <shape type="rectangle"><transform name="to_world"><scale value="1.5"/></transform>
    <bsdf type="roughconductor"/></shape>
</scene>"""


@pytest.mark.parametrize("depth", [2, 3])
def test_deferred_vertex_work_is_the_same_image(tmp_path, monkeypatch, depth):
    """Draws and interaction inside the vertex branch (``deferred``) against both before it:
    the same image bit for bit, three paths per lane, at depths 2 and 3 (a second
    vertex after the first). Negative control: a jump one draw short of the vertex's draws
    changes the image (the comparison sees the random numbers)."""
    (tmp_path / "s.xml").write_text(FLOATING_XML.format(depth=depth))
    scene = load_scene(tmp_path / "s.xml")

    def image(deferred):
        monkeypatch.setattr(PathIntegrator, "deferred", deferred)
        # independent: the PCG32 stream whose draws VERTEX_DRAWS counts (a low-discrepancy
        # sampler's dimensions do not depend on it)
        r = Renderer(scene, RenderOptions(width=64, height=48, spp=18, seed=3, progress=False,
                                          sampler="independent", path=PathOptions(max_depth=depth)))
        assert r.integrator.straight and not r.scene.materials.has_emission
        return r.render().image

    before = image(False)
    assert (before > 0).mean() > 0.3 and (before == 0).mean() > 0.2  # hits and escapes
    np.testing.assert_array_equal(image(True), before)
    monkeypatch.setattr(path, "VERTEX_DRAWS", path.VERTEX_DRAWS - 1)
    assert not np.array_equal(image(True), before)


@pytest.mark.skipif(embree_lib.reason() is not None, reason=f"{embree_lib.reason()}")
def test_camera_rays_culled_by_the_shape_boxes_are_the_same_image(tmp_path, monkeypatch):
    """The unrolled path's camera rays query the accelerator (Embree) only where they reach a
    shape's box (``cull``, label ``drpt_cull``): the image of every ray querying it, bit for
    bit. Negative control: boxes that leave out the floor lose its pixels."""
    (tmp_path / "s.xml").write_text(FLOATING_XML.format(depth=2))
    scene = load_scene(tmp_path / "s.xml")
    labels = []
    if_stmt = dr.if_stmt
    monkeypatch.setattr(dr, "if_stmt",
                        lambda *a, label=None, **k: labels.append(label) or if_stmt(*a, label=label, **k))

    def image(cull, boxes=None):
        monkeypatch.setattr(PathIntegrator, "cull", cull)
        labels.clear()
        r = Renderer(scene, RenderOptions(width=64, height=48, spp=6, seed=2, progress=False, accel="embree",
                                          path=PathOptions(max_depth=2)))
        assert r.scene.boxes is not None and len(r.scene.boxes) == 2
        if boxes is not None:
            r.scene.boxes = boxes(r.scene.boxes)
        out = r.render().image
        assert ("drpt_cull" in labels) == cull
        return out

    culled = image(True)
    np.testing.assert_array_equal(culled, image(False))
    sphere_only = image(True, lambda b: ShapeBoxes(b.lo[1:].astype(float), b.hi[1:].astype(float)))
    assert (sphere_only == 0).mean() > (culled == 0).mean() + 0.1


@pytest.mark.skipif(embree_lib.reason() is not None, reason=f"{embree_lib.reason()}")
def test_a_camera_inside_a_shape_box_traces_no_culling(tmp_path, monkeypatch):
    """Where a shape's box holds the camera (inside a room; here inside the sphere) every
    camera ray reaches that box, so the scene has no culling boxes and the kernel no
    ``drpt_cull`` branch; a thin lens whose aperture leaves the box keeps them (the lens's
    cube around the center must lie inside). The camera outside (the test above) keeps them."""
    labels = []
    if_stmt = dr.if_stmt
    monkeypatch.setattr(dr, "if_stmt",
                        lambda *a, label=None, **k: labels.append(label) or if_stmt(*a, label=label, **k))
    inside = FLOATING_XML.format(depth=2).replace('origin="0, -4, 3"', 'origin="0, 0.1, 1"')
    (tmp_path / "in.xml").write_text(inside)
    r = Renderer(load_scene(tmp_path / "in.xml"), RenderOptions(width=16, height=8, spp=2, progress=False,
                                                                accel="embree", path=PathOptions(max_depth=2)))
    assert r.scene.boxes is None
    r.render()
    assert "drpt_cull" not in labels
    boxes = ShapeBoxes.of(load_scene(tmp_path / "in.xml"))
    assert boxes.hold((0.0, 0.1, 1.0), 0.1) and not boxes.hold((0.0, 0.1, 1.0), 1.0)
