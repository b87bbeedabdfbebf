"""Rays leaving a convex shape (drpt/render/integrators/path.py, ``PathIntegrator.cull_leaving``):
in a scene of mirrors only (the bounce loop) and in short paths (unrolled: their last segment's
any-hit query and next-event estimation's shadow rays), every ray query runs on the lanes whose
ray reaches a shape's box, the box of the convex shape it leaves outward left out; the image is
that of every ray querying the accelerator, bit for bit."""

import drjit as dr
import numpy as np
import pytest

from drpt.accel import embree_lib
from drpt.accel.boxes import FLAT
from drpt.options import PathOptions, RenderOptions
from drpt.render.integrators.path import PathIntegrator
from drpt.render.renderer import Renderer
from drpt.scene import load_scene
from support.accel import icosphere

#: spheres, a cube and a bowl (open: not convex; its inside sees itself) under a constant sky and
#: a point light, all of one material ``m``
MIRRORS_XML = """<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="{depth}"/></integrator>
  <sensor type="perspective">
    <transform name="to_world"><lookat origin="1, 2, 5" target="0, 0, -0.3" up="0, 0, 1"/></transform>
    <film type="hdrfilm"><integer name="width" value="40"/><integer name="height" value="32"/>
      <rfilter type="box"/></film>
    <sampler type="independent"><integer name="sample_count" value="4"/></sampler>
  </sensor>
  <emitter type="constant"><rgb name="radiance" value="1, 0.8, 0.6"/></emitter>
  <emitter type="point"><point name="position" x="0.3" y="0.2" z="3"/><rgb name="intensity" value="3"/></emitter>
  {bsdf}
  <shape type="sphere"><point name="center" x="1.5" y="-0.6" z="0.3"/><float name="radius" value="0.3"/>
    <ref id="m"/></shape>
  <shape type="sphere"><point name="center" x="-0.6" y="1.5" z="0.3"/><float name="radius" value="0.3"/>
    <ref id="m"/></shape>
  <shape type="cube"><transform name="to_world"><scale value="0.3"/><translate x="1.4" y="1" z="0.2"/></transform>
    <ref id="m"/></shape>
  <shape type="obj"><string name="filename" value="bowl.obj"/><ref id="m"/></shape>
</scene>"""

def bowl_obj() -> str:
    """An OBJ of the lower half of an icosphere of radius 1 at the origin, open at the top: a
    mirror bowl whose inside sees itself."""
    v, f = icosphere(2)
    f = f[v[f][:, :, 2].max(axis=1) <= 1e-9]
    return "".join(f"v {x} {y} {z}\n" for x, y, z in v) + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in f)


@pytest.mark.skipif(embree_lib.reason() is not None, reason=f"{embree_lib.reason()}")
@pytest.mark.parametrize("depth, bsdf", [
    (8, '<bsdf type="conductor" id="m"><string name="material" value="Au"/></bsdf>'),  # mirrors: the loop
    (2, '<bsdf type="twosided" id="m"><bsdf type="diffuse"/></bsdf>'),  # short paths, next-event estimation
])
def test_rays_leaving_convex_shapes_skip_their_boxes_the_same_image(tmp_path, monkeypatch, depth, bsdf):
    """The queries cull by the boxes (label ``drpt_cull``), the spheres' and the cube's left
    out for rays leaving them, the bowl's never (not closed): the same image bit for bit as
    without culling, gold mirrors in the bounce loop (depth 8) and diffuse shapes in the
    unrolled path (depth 2: the shadow rays and the last segment). Negative control: the bowl
    taken for convex loses the light it reflects inside itself (gold), or lets its walls'
    shadows through (diffuse)."""
    (tmp_path / "s.xml").write_text(MIRRORS_XML.format(depth=depth, bsdf=bsdf))
    (tmp_path / "bowl.obj").write_text(bowl_obj())
    scene = load_scene(tmp_path / "s.xml")
    labels = []
    if_stmt = dr.if_stmt
    monkeypatch.setattr(dr, "if_stmt",
                        lambda *a, label=None, **k: labels.append(label) or if_stmt(*a, label=label, **k))

    def image(cull, bowl_convex=False):
        monkeypatch.setattr(PathIntegrator, "cull", cull)
        labels.clear()
        r = Renderer(scene, RenderOptions(width=40, height=32, spp=4, seed=3, progress=False, accel="embree",
                                          sampler="independent", path=PathOptions(max_depth=depth)))
        boxes = r.scene.boxes
        assert sorted(boxes.outward) == [0, 1, 1, 1]
        if bowl_convex:  # (its inside is its triangles' back: they face out of the icosphere)
            boxes._outward = np.where(boxes.outward == 0, -1, boxes.outward)
        assert r.integrator.pixel_coherent == (depth == 8) and r.integrator.cull_leaving == cull
        out = r.render().image
        assert ("drpt_cull" in labels) == cull
        return out

    culled = image(True)
    assert np.isfinite(culled).all() and culled.mean() > 0.1
    np.testing.assert_array_equal(culled, image(False))
    wrong = image(True, bowl_convex=True)
    diff = np.abs(wrong - culled).max(axis=2)  # (the pixels whose rays meet the bowl again)
    assert (diff > 0).sum() >= 4 and diff.max() > 0.05


#: the mirrors' camera and lights, a rough metal sphere and bowl (two-sided) on a floor rectangle
#: (flat), unbounded depth: the bounce loop of a scene with glossy BSDFs
GROUND_XML = MIRRORS_XML[:MIRRORS_XML.index("  {bsdf}")].replace("{depth}", "-1") + """\
  <bsdf type="twosided" id="m"><bsdf type="roughconductor"><float name="alpha" value="0.2"/></bsdf></bsdf>
  <bsdf type="twosided" id="floor"><bsdf type="roughplastic"><float name="alpha" value="0.1"/></bsdf></bsdf>
  <shape type="sphere"><point name="center" x="1.5" y="-0.6" z="0.3"/><float name="radius" value="0.3"/>
    <ref id="m"/></shape>
  <shape type="obj"><string name="filename" value="bowl.obj"/><ref id="m"/></shape>
  <shape type="rectangle"><transform name="to_world"><scale value="6"/><translate z="-1"/></transform>
    <ref id="floor"/></shape>
</scene>"""


@pytest.mark.skipif(embree_lib.reason() is not None, reason=f"{embree_lib.reason()}")
def test_rays_leaving_a_floor_skip_its_box_in_the_bounce_loop(tmp_path, monkeypatch):
    """With a flat shape (the floor) the bounce loop of glossy paths culls every query by the
    boxes, the floor's left out for rays leaving it to either side and the sphere's for rays
    leaving it outward: the same image bit for bit as without culling. Negative control: the
    bowl (open, not flat) taken for flat loses the light it reflects inside itself."""
    (tmp_path / "s.xml").write_text(GROUND_XML)
    (tmp_path / "bowl.obj").write_text(bowl_obj())
    scene = load_scene(tmp_path / "s.xml")

    def image(cull, bowl_flat=False):
        monkeypatch.setattr(PathIntegrator, "cull", cull)
        r = Renderer(scene, RenderOptions(width=40, height=32, spp=4, seed=3, progress=False, accel="embree",
                                          sampler="independent"))
        boxes = r.scene.boxes
        assert sorted(boxes.outward) == [0, 1, FLAT] and boxes.flat
        if bowl_flat:
            boxes._outward = np.where(boxes.outward == 0, FLAT, boxes.outward)
        assert not r.integrator.pixel_coherent and not r.integrator.straight
        assert r.integrator.cull_leaving == cull
        return r.render().image

    culled = image(True)
    assert np.isfinite(culled).all() and culled.mean() > 0.1
    np.testing.assert_array_equal(culled, image(False))
    diff = np.abs(image(True, bowl_flat=True) - culled).max(axis=2)
    assert (diff > 0).sum() >= 4 and diff.max() > 0.05
