"""PathIntegrator's two entry points: one path per lane (``sample``) and path
regeneration (``sample_sequence``, what the renderer runs); short paths traced unrolled
(straight-line code, ``PathIntegrator.unrolled``) against the bounce loop."""

from pathlib import Path

import drjit as dr
import numpy as np
import pytest
from drjit.auto import PCG32, Bool, Float, UInt32

from drpt.accel import embree_lib
from drpt.options import PathOptions, RenderOptions
from drpt.render.integrators import path as path_module
from drpt.render.integrators.path import PathIntegrator, coherent_shadows, nothing_seen
from drpt.render.renderer import Renderer
from drpt.scene import load_scene

needs_embree = pytest.mark.skipif(embree_lib.reason() is not None, reason=f"{embree_lib.reason()}")

W = H = 32


def _renderer(scene_path, bsdf):
    return Renderer(load_scene(scene_path), RenderOptions(width=W, height=H, spp=16, bsdf=bsdf,
                                                             progress=False))


def _camera_ray(r, pixel):
    """Jittered camera rays through ``pixel`` (one per lane)."""
    x, y = Float(pixel % W), Float(pixel // W)
    return lambda rng: r.camera.ray(x + rng.next_float32(), y + rng.next_float32())


def test_first_regenerated_path_is_the_single_path(scenes_dir):
    """With one path per lane and the same random stream, sample_sequence's
    sum is exactly sample()'s radiance, and its square sum the square: the
    regeneration loop adds nothing and loses nothing."""
    r = _renderer(scenes_dir / "cornellbox/cornellbox.txt", "phong")
    n = W * H
    camera_ray = _camera_ray(r, dr.arange(UInt32, n))
    rng = PCG32(n, initstate=7)
    o, d = camera_ray(rng)
    L = r.integrator.sample(rng, o, d, Bool(True))
    acc, acc2, dropped = r.integrator.sample_sequence(PCG32(n, initstate=7), camera_ray,
                                                      dr.full(UInt32, 1, n))
    dr.eval(L, acc, acc2, dropped)
    assert np.array_equal(acc.numpy(), L.numpy())
    assert np.array_equal(acc2.numpy(), (L * L).numpy())
    assert dr.sum(dropped)[0] == 0
    assert (L.numpy() > 0).mean() > 0.5  # most values are lit: a real comparison


@pytest.mark.slow
def test_sequence_mean_matches_independent_paths(scenes_dir):
    """k paths one after another in a lane estimate the same image as k lanes
    with one path each (newscene, Cook-Torrance): per color channel, the image
    sums agree within 5 standard errors (~1.8% here: a 3% loss in the
    sequence's sums fails it)."""
    r = _renderer(scenes_dir / "newscene/newscene.txt", "cook-torrance")
    n, k = W * H, 256
    acc, acc2, _ = r.integrator.sample_sequence(
        PCG32(n, initstate=1), _camera_ray(r, dr.arange(UInt32, n)), dr.full(UInt32, k, n))
    seq = acc.numpy() / k  # (3, n) pixel means
    seq_var = np.maximum(acc2.numpy() / k - seq**2, 0.0) / k  # variance of each mean

    rng = PCG32(n * k, initstate=2)
    o, d = _camera_ray(r, dr.arange(UInt32, n * k) // k)(rng)  # k adjacent lanes per pixel
    L = r.integrator.sample(rng, o, d, Bool(True))
    single = np.stack([dr.block_sum(c, k).numpy() for c in (L.x, L.y, L.z)]) / k
    sq = np.stack([dr.block_sum(c * c, k).numpy() for c in (L.x, L.y, L.z)]) / k
    single_var = np.maximum(sq - single**2, 0.0) / k
    for c in range(3):
        diff = (seq[c] - single[c]).sum()
        se = np.sqrt(seq_var[c].sum() + single_var[c].sum())
        assert se > 0 and abs(diff) < 5 * se, (c, diff, se)


# ------------------------------------------------------------ unrolled short paths
def _depth_renderer(scene, depth, hide=False):
    return Renderer(scene, RenderOptions(width=W, height=H, spp=16, bsdf="phong", progress=False,
                                         path=PathOptions(max_depth=depth, hide_emitters=hide)))


def _spot_without_sky():
    """tests/data/xml/spot.xml without its constant sky: a spot light only, nothing a ray can see."""
    from dataclasses import replace

    from drpt.scene.model import Background
    from support.xml import XML

    return replace(load_scene(XML / "spot.xml"), background=Background((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)))


def _one_path_per_lane(r, unrolled, monkeypatch, seed=7):
    monkeypatch.setattr(PathIntegrator, "unrolled", unrolled)
    n = W * H
    rng = PCG32(n, initstate=seed)
    o, d = _camera_ray(r, dr.arange(UInt32, n))(rng)
    L = r.integrator.sample(rng, o, d, Bool(True))
    dr.eval(L)
    return L.numpy()


@pytest.mark.parametrize("case, depth", [("cornell", 1), ("cornell", 2), ("cornell", 3),
                                         ("spot", 1), ("spot", 2), ("hidden", 1), ("hidden", 2)])
def test_unrolled_path_is_the_loops_path(scenes_dir, monkeypatch, case, depth):
    """One path per lane, the same random stream: the unrolled path (camera ray, full vertices,
    a last segment that only looks for emitters) gives the bounce loop's radiance bit for bit,
    with an area light (Cornell box), with a spot light only (nothing a ray can see: the last
    segment is not traced) and with hide_emitters (the camera ray sees what lies behind the
    area lights of tests/data/xml/hide_emitters.xml). Negative control: the loop one segment
    deeper differs."""
    from support.xml import XML

    scene = {"cornell": lambda: load_scene(scenes_dir / "cornellbox/cornellbox.txt"),
             "spot": _spot_without_sky,
             "hidden": lambda: load_scene(XML / "hide_emitters.xml")}[case]()
    r = _depth_renderer(scene, depth, hide=case == "hidden")
    assert r.integrator.straight and type(r.integrator) is PathIntegrator
    assert nothing_seen(r.scene) == (case == "spot")
    unrolled = _one_path_per_lane(r, True, monkeypatch)
    assert np.array_equal(unrolled, _one_path_per_lane(r, False, monkeypatch))
    # a real comparison: lit pixels (at depth 1 only the light itself, or with a spot light
    # or hide_emitters nothing: black is the right image)
    lit = 0.2 if depth > 1 else {"cornell": 0.005, "spot": 0.0, "hidden": 0.0}[case]
    assert (unrolled > 0).mean() >= lit
    deeper = _depth_renderer(scene, depth + 1, hide=case == "hidden")
    assert not np.array_equal(unrolled, _one_path_per_lane(deeper, False, monkeypatch))


def test_unrolled_only_for_short_fixed_depths(scenes_dir):
    """Depths 1 to UNROLLED_MAX_DEPTH are unrolled; deeper and unbounded paths run the loop, and
    so does volpath (a bounce of its own: media along the last segment too)."""
    from drpt.render.integrators.path import UNROLLED_MAX_DEPTH
    from drpt.render.integrators.volpath import VolPathIntegrator

    scene = load_scene(scenes_dir / "cornellbox/cornellbox.txt")
    assert _depth_renderer(scene, UNROLLED_MAX_DEPTH).integrator.straight
    assert not _depth_renderer(scene, UNROLLED_MAX_DEPTH + 1).integrator.straight
    assert not _depth_renderer(scene, -1).integrator.straight
    fog = Renderer(load_scene(scenes_dir / "cornellbox_media/cornellbox_media.txt"),
                   RenderOptions(width=W, height=H, spp=1, integrator="volpath", progress=False,
                                 path=PathOptions(max_depth=2)))
    assert isinstance(fog.integrator, VolPathIntegrator) and not fog.integrator.straight


def _sequence_means(r, unrolled, monkeypatch, seed, k):
    """Per-pixel means of ``k`` regenerated paths per lane and the variances of the means."""
    monkeypatch.setattr(PathIntegrator, "unrolled", unrolled)
    n = W * H
    acc, acc2, dropped = r.integrator.sample_sequence(
        PCG32(n, initstate=seed), _camera_ray(r, dr.arange(UInt32, n)), dr.full(UInt32, k, n))
    dr.eval(acc, acc2, dropped)
    assert dr.sum(dropped)[0] == 0
    mean = acc.numpy() / k
    return mean, np.maximum(acc2.numpy() / k - mean**2, 0.0) / k


@pytest.mark.parametrize("depth", [1, 2])
def test_unrolled_sequence_mean_matches_the_loop(scenes_dir, monkeypatch, depth):
    """Path regeneration, 64 paths per lane on the Cornell box: the unrolled sequence's image
    sum agrees with the loop's (other random streams) within 5 standard errors per channel (a
    pure-noise |z| above 5 has probability 6e-7). Negative control: the loop two segments deeper
    (the direct light the unrolled depth 1 lacks; two more bounces after depth 2) is more than 5
    standard errors away."""
    scene = load_scene(scenes_dir / "cornellbox/cornellbox.txt")
    r = _depth_renderer(scene, depth)
    a, va = _sequence_means(r, True, monkeypatch, 1, 64)
    b, vb = _sequence_means(r, False, monkeypatch, 2, 64)
    c, vc = _sequence_means(_depth_renderer(scene, depth + 2), False, monkeypatch, 2, 64)
    for ch in range(3):
        se = np.sqrt(va[ch].sum() + vb[ch].sum())
        assert se > 0 and abs((a[ch] - b[ch]).sum()) < 5 * se, (ch, (a[ch] - b[ch]).sum(), se)
        se_c = np.sqrt(va[ch].sum() + vc[ch].sum())
        assert abs((a[ch] - c[ch]).sum()) > 5 * se_c, (ch, (a[ch] - c[ch]).sum(), se_c)


def _record_if_labels(monkeypatch) -> list:
    """The labels of the symbolic ``if`` statements traced from now on (``dr.if_stmt``
    wrapped for the test), in order."""
    labels = []
    if_stmt = dr.if_stmt

    def recording(*args, **kw):
        labels.append(kw.get("label"))
        return if_stmt(*args, **kw)

    monkeypatch.setattr(dr, "if_stmt", recording)
    return labels


MIXED_XML = """<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="{depth}"/></integrator>
  <sensor type="perspective">
    <transform name="to_world"><lookat origin="0, 0, -5" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="12"/><integer name="height" value="8"/>
      <rfilter type="box"/></film>
  </sensor>
  <emitter type="constant"><rgb name="radiance" value="0.5"/></emitter>
  <shape type="sphere"><point name="center" x="-1.05" y="0" z="0"/><bsdf type="{left}"/></shape>
  <shape type="sphere"><point name="center" x="1.05" y="0" z="0"/><bsdf type="diffuse"/></shape>
  <shape type="rectangle">
    <transform name="to_world"><lookat origin="0, 3, 0" target="0, 0, 0" up="0, 0, 1"/></transform>
    <emitter type="area"><rgb name="radiance" value="5"/></emitter>
  </shape>
</scene>"""


@pytest.mark.parametrize("depth", [2, 6])  # unrolled and the bounce loop
@pytest.mark.parametrize("left,branched", [("conductor", True), ("diffuse", False)])
def test_nee_branch_on_smooth_lanes_is_the_masked_estimate(tmp_path, monkeypatch, depth, left, branched):
    """In a scene with delta-only and smooth materials next-event estimation runs in a
    symbolic ``if`` on the lanes off delta-only materials (``drpt_nee``): the same random
    numbers and the same image, bit for bit, as every lane estimating masked (zero on a
    mirror) and the BSDF sampled in a dispatch of its own (the branch samples the mirror's
    lanes in its other arm, the others in the estimate's BSDF dispatch). A scene without
    delta materials (the control) traces no such branch."""
    (tmp_path / "s.xml").write_text(MIXED_XML.format(depth=depth, left=left))
    scene = load_scene(tmp_path / "s.xml")
    labels = _record_if_labels(monkeypatch)

    def image():
        return Renderer(scene, RenderOptions(width=12, height=8, spp=8, progress=False,
                                             path=PathOptions(max_depth=depth))).render().image

    branch = image()
    assert ("drpt_nee" in labels) == branched
    def masked(self, scene, si, beta, L, u_sel, u_light, u_path, active, *_):
        L = L + beta * self.direct.emitter(si, u_sel, u_light, active, mis=True)
        return (L, *scene.sample_bsdf(si, u_path[0], u_path[1]))

    monkeypatch.setattr(PathIntegrator, "_nee", masked)
    masked = image()
    assert masked.max() > 0.0
    np.testing.assert_array_equal(branch, masked)


@pytest.mark.parametrize("depth", [2, 3])
def test_branched_vertex_is_the_straight_line_vertex(tmp_path, monkeypatch, depth):
    """The unrolled path's vertices and its last segment run in symbolic ``if`` statements on
    their live lanes (``drpt_vertex``, ``drpt_last``; :attr:`PathIntegrator.branched`), the
    vertices drawing their random numbers before theirs: the image, over several paths per
    lane, is the straight-line masked path's bit for bit, in a scene where most rays escape
    to the sky (so that whole packets skip). Negative control: another seed's image differs
    (the comparison sees the random numbers)."""
    (tmp_path / "s.xml").write_text(MIXED_XML.format(depth=depth, left="diffuse"))
    scene = load_scene(tmp_path / "s.xml")
    labels = _record_if_labels(monkeypatch)

    def image(branched, seed=0):
        monkeypatch.setattr(PathIntegrator, "branched", branched)
        labels.clear()
        r = Renderer(scene, RenderOptions(width=24, height=16, spp=8, seed=seed, progress=False,
                                          path=PathOptions(max_depth=depth)))
        assert r.integrator.straight
        return r.render().image, (labels.count("drpt_vertex"), labels.count("drpt_last"))

    branch, n_branch = image(True)
    masked, n_masked = image(False)
    assert min(n_branch) > 0 and n_masked == (0, 0)  # (traced once per pass)
    assert masked.max() > 0.0 and (masked == 0.0).mean() < 0.5
    np.testing.assert_array_equal(branch, masked)
    assert not np.array_equal(branch, image(True, seed=1)[0])


def test_the_loops_vertices_run_in_a_branch_as_the_masked_loop(tmp_path, monkeypatch):
    """Where a lane traces one sample (a tree accelerator), the bounce loop's vertices run in
    a symbolic ``if`` on their live lanes (``drpt_vertex``; :attr:`PathIntegrator.loop_branched`),
    their random numbers drawn before it: the image and variance are the masked loop's bit
    for bit (paths to depth 6 between a mirror and a diffuse sphere under a sky, most camera
    rays escaping, so that whole packets skip). Negative control: another seed's image
    differs. A medium's bounce (volpath's own) traces no such branch and renders."""
    (tmp_path / "s.xml").write_text(MIXED_XML.format(depth=6, left="conductor"))
    scene = load_scene(tmp_path / "s.xml")
    labels = _record_if_labels(monkeypatch)

    def render(branched, seed=0, xml_scene=scene, integrator="path"):
        monkeypatch.setattr(PathIntegrator, "loop_branched", branched)
        labels.clear()
        r = Renderer(xml_scene, RenderOptions(width=24, height=16, spp=8, seed=seed, progress=False, accel="bvh",
                                              integrator=integrator, path=PathOptions(max_depth=6)))
        assert not r.integrator.straight
        return r.render(), labels.count("drpt_vertex")

    (branch, n_branch), (masked, n_masked) = render(True), render(False)
    assert n_branch > 0 and n_masked == 0
    assert masked.image.max() > 0.0 and (masked.image == 0.0).mean() < 0.5
    np.testing.assert_array_equal(branch.image, masked.image)
    np.testing.assert_array_equal(branch.variance, masked.variance)
    assert not np.array_equal(branch.image, render(True, seed=1)[0].image)
    fog = MIXED_XML.format(depth=6, left="diffuse").replace(
        '<integrator type="path">', '<integrator type="volpath">').replace(
        '<bsdf type="diffuse"/></shape>\n  <shape type="rectangle">',
        '<bsdf type="null"/><medium type="homogeneous" name="interior"><float name="sigma_t" value="2"/>'
        '</medium></shape>\n  <shape type="rectangle">')
    (tmp_path / "fog.xml").write_text(fog)
    volume, n_volume = render(True, xml_scene=load_scene(tmp_path / "fog.xml"), integrator="volpath")
    assert n_volume == 0 and volume.image.max() > 0.0 and np.all(np.isfinite(volume.image))


def _unoccluded(self, scene, s, L):
    """``_look_at_emitters`` without its shadow ray: the negative control's bug."""
    from drpt.render.integrators.path import add_emission

    hit = scene.emissive.intersect(s.o, s.d, s.active)
    hit.valid = s.active & hit.valid
    return (add_emission(scene, self.opt, scene.interaction(s.o, s.d, hit), s, L, s.active),)


@needs_embree
@pytest.mark.parametrize("depth", [2, 3])
def test_last_segment_finds_emitters_first_as_the_closest_hit_does(scenes_dir, tmp_path, monkeypatch, depth):
    """Where a few emissive triangles are all a ray can see (the Cornell box's light), the
    unrolled path's last segment looks for them first and traces one shadow ray up to the one
    it hits (``PathIntegrator.emitters_first``), instead of every ray's closest hit. Through
    Embree (the closest hit's own triangle test) the image agrees with the closest hit's to
    float rounding: every pixel within 1e-5 relative (the light's distance and barycentrics
    from another test). Negative control: without the shadow ray (light seen through the
    boxes, weighted down by MIS) pixels differ beyond that, and by over 100x the rounding."""
    scene = load_scene(scenes_dir / "cornellbox/cornellbox.txt")

    def image(first, look=None):
        monkeypatch.setattr(PathIntegrator, "emitter_first", first)
        if look is not None:
            monkeypatch.setattr(PathIntegrator, "_look_at_emitters", look)
        r = Renderer(scene, RenderOptions(width=24, height=24, spp=8, progress=False, accel="embree",
                                          path=PathOptions(max_depth=depth)))
        assert r.integrator.emitters_first == first
        return r.render().image

    first, closest = image(True), image(False)
    assert (first > 0).mean() > 0.5
    np.testing.assert_allclose(first, closest, rtol=1e-5, atol=1e-7)
    unblocked = image(True, _unoccluded)
    assert not np.allclose(unblocked, closest, rtol=1e-5, atol=1e-7)
    assert np.abs(unblocked - closest).max() > 100 * np.abs(first - closest).max()


def _sky_through_occluders(self, scene, s, L):
    """``_look_at_emitters`` where a blocked ray still sees the sky: the negative control's bug."""
    from drpt.render.integrators.path import add_emission

    if scene.emissive is not None:
        hit = scene.emissive.intersect(s.o, s.d, s.active)
    else:  # (no emissive surface: a miss everywhere)
        hit = scene.intersect_preliminary(s.o, s.d, s.active & False)
    near = s.active & hit.valid
    si = scene.interaction(s.o, s.d, hit)
    si.valid = near & ~scene.occluded(s.o, s.d, si.t * 0.999, near)
    return (add_emission(scene, self.opt, si, s, L, s.active),)


@pytest.mark.parametrize("accel", ["auto", "bvh", pytest.param("embree", marks=needs_embree)])
@pytest.mark.parametrize("light", [True, False])
@pytest.mark.parametrize("depth", [2, 3])
def test_last_segment_with_a_sky_finds_emitters_first_as_the_closest_hit_does(tmp_path, monkeypatch, depth,
                                                                                light, accel):
    """With a sky, the unrolled path's last segment also looks for the emissive triangles first
    (``PathIntegrator.emitters_first``) and traces one any-hit ray, up to the emitter it hits
    or to infinity, where the closest hit traced one closest-hit query: two spheres side by
    side (each blocks part of the other's sky) under a panel light (``light``; without it, no
    emissive surface: the shadow ray alone). The images agree with the closest hit's to float
    rounding (every pixel within 1e-5 relative; without emissive surfaces bit for bit: the
    same accelerator's hit or no hit). Negative control: a blocked ray that still sees the
    sky (the shadow ray's answer dropped for the sky) differs beyond that. Through the inline
    list (``auto`` here), drpt's BVH and Embree."""
    xml = MIXED_XML.format(depth=depth, left="diffuse")
    if not light:
        xml = xml[:xml.index('  <shape type="rectangle">')] + "</scene>"
    (tmp_path / "s.xml").write_text(xml)
    scene = load_scene(tmp_path / "s.xml")

    def image(first, look=None):
        monkeypatch.setattr(PathIntegrator, "emitter_first", first)
        if look is not None:
            monkeypatch.setattr(PathIntegrator, "_look_at_emitters", look)
        r = Renderer(scene, RenderOptions(width=24, height=16, spp=8, progress=False, accel=accel,
                                          path=PathOptions(max_depth=depth)))
        assert r.integrator.emitters_first == first and (r.scene.emissive is not None) == light
        return r.render().image

    first, closest = image(True), image(False)
    assert (first > 0).mean() > 0.9
    if light:
        np.testing.assert_allclose(first, closest, rtol=1e-5, atol=1e-7)
    else:
        np.testing.assert_array_equal(first, closest)
    leaky = image(True, _sky_through_occluders)
    assert not np.allclose(leaky, closest, rtol=1e-5, atol=1e-7)


#: a floor under a 2x2 panel light at y = 2 (facing down) with a diffuser over half of it
#: ``gap`` below the panel
DIFFUSER_XML = """<scene version="3.0.0">
  <sensor type="perspective">
    <transform name="to_world"><lookat origin="0, 1, -4" target="0, 0.5, 0" up="0, 1, 0"/></transform>
  </sensor>
  <shape type="rectangle"><bsdf type="diffuse"/>
    <transform name="to_world"><scale value="3"/><lookat origin="0, 0, 0" target="0, 1, 0" up="0, 0, 1"/></transform>
  </shape>
  <shape type="rectangle">
    <transform name="to_world"><lookat origin="0, 2, 0" target="0, 0, 0" up="0, 0, 1"/></transform>
    <emitter type="area"><rgb name="radiance" value="5"/></emitter>
  </shape>
  <shape type="rectangle"><bsdf type="diffuse"/>
    <transform name="to_world"><scale x="0.5" y="1" z="1"/>
      <lookat origin="0.5, {y}, 0" target="0.5, 0, 0" up="0, 0, 1"/></transform>
  </shape>
</scene>"""


def _short_of_emitter(self, scene, s, L):
    """``_look_at_emitters`` with its shadow ray stopped a relative ``2**-12`` short of the
    emitter (next-event estimation's ``SHADOW_SHRINK``): the negative control's rule."""
    from drpt.render.integrators.common import SHADOW_SHRINK
    from drpt.render.integrators.path import add_emission

    hit = scene.emissive.intersect(s.o, s.d, s.active)
    near = s.active & hit.valid
    hit.valid = near & ~scene.occluded(s.o, s.d, hit.t * SHADOW_SHRINK, near)
    return (add_emission(scene, self.opt, scene.interaction(s.o, s.d, hit), s, L, s.active),)


@pytest.mark.parametrize("accel", ["embree", "bvh"])
def test_emitters_first_sees_a_diffuser_just_in_front_of_the_light(tmp_path, monkeypatch, accel):
    """A diffuser 5e-5 in front of a panel light (2 to 4 units from the floor points whose
    rays reach it: far inside a relative 2**-12, far outside float rounding) blocks the
    emitters-first shadow ray as the closest hit finds it first: every pixel within 1e-5
    relative of the closest hit's image. Negative control: a shadow ray stopped a relative
    2**-12 short of the light (next-event estimation's rule) misses the diffuser and sees
    the light through it, beyond that tolerance and by over 100x the rounding."""
    (tmp_path / "s.xml").write_text(DIFFUSER_XML.replace("{y}", repr(2.0 - 5e-5)))
    scene = load_scene(tmp_path / "s.xml")

    def image(first, look=None):
        monkeypatch.setattr(PathIntegrator, "emitter_first", first)
        if look is not None:
            monkeypatch.setattr(PathIntegrator, "_look_at_emitters", look)
        r = Renderer(scene, RenderOptions(width=24, height=24, spp=8, progress=False, accel=accel,
                                          path=PathOptions(max_depth=2)))
        assert r.integrator.emitters_first == first
        return r.render().image

    first, closest = image(True), image(False)
    assert (first > 0).mean() > 0.3  # (the floor)
    np.testing.assert_allclose(first, closest, rtol=1e-5, atol=1e-7)
    short = image(True, _short_of_emitter)
    assert not np.allclose(short, closest, rtol=1e-5, atol=1e-7)
    assert np.abs(short - closest).max() > 100 * np.abs(first - closest).max()


SPHERE_LIT_XML = """<scene version="3.0.0">
  <sensor type="perspective">
    <transform name="to_world"><lookat origin="0, 0, -4" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="12"/>
      <rfilter type="box"/></film>
  </sensor>
  <emitter type="point"><point name="position" x="-2" y="3" z="-3"/><rgb name="intensity" value="20"/></emitter>
  {sky}
  <shape type="obj"><string name="filename" value="{obj}"/><bsdf type="diffuse"/></shape>
  <shape type="rectangle"><transform name="to_world"><scale value="4"/><translate z="2"/></transform>
    <bsdf type="diffuse"/></shape>
</scene>"""


@needs_embree
@pytest.mark.parametrize("depth", [2, 5])  # unrolled and the bounce loop
def test_coherent_shadow_rays_change_no_pixel(tmp_path, monkeypatch, depth):
    """Next-event estimation's shadow rays at the camera rays' hits are coherent Embree queries
    where no emitter at infinity but delta ones can be chosen (:func:`coherent_shadows`: a point
    light, not with an environment map): a traversal hint, so the image is the same, bit for bit,
    as with every shadow ray incoherent. The control that the hint reaches the queries: the
    recorded ``coherent`` arguments of the shadow queries are a Bool with the hint, False
    without it."""
    from drpt.render.scene import DeviceScene

    obj = Path(__file__).resolve().parents[2] / "data" / "xml" / "uvsphere.obj"
    sky_map = f'<emitter type="envmap"><string name="filename" value="{obj.parent / "sky.exr"}"/></emitter>'
    # (a constant emitter is the background, which next-event estimation does not sample)
    for sky, expect in (("", True), ('<emitter type="constant"><rgb name="radiance" value="0.2"/></emitter>', True),
                        (sky_map, False)):
        (tmp_path / "s.xml").write_text(SPHERE_LIT_XML.format(sky=sky, obj=obj))
        scene = load_scene(tmp_path / "s.xml")
        opts = RenderOptions(width=16, height=12, spp=8, accel="embree", progress=False,
                             path=PathOptions(max_depth=depth))
        assert coherent_shadows(Renderer(scene, opts).scene) is expect
    seen = []
    occluded = DeviceScene.occluded

    def spy(self, o, d, tmax, active, coherent=False, **kw):
        seen.append(coherent)
        return occluded(self, o, d, tmax, active, coherent, **kw)

    monkeypatch.setattr(DeviceScene, "occluded", spy)
    (tmp_path / "s.xml").write_text(SPHERE_LIT_XML.format(sky="", obj=obj))
    r = Renderer(load_scene(tmp_path / "s.xml"), RenderOptions(width=16, height=12, spp=8, accel="embree",
                                                              progress=False, path=PathOptions(max_depth=depth)))
    hinted = r.render().image
    assert seen and all(isinstance(c, Bool) for c in seen)
    seen.clear()
    monkeypatch.setattr(path_module, "coherent_shadows", lambda scene: False)
    plain = r.render().image
    assert seen and all(c is False for c in seen)
    assert plain.max() > 0.0
    np.testing.assert_array_equal(hinted, plain)


MASK_XML = """<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="2"/></integrator>
  <sensor type="perspective">
    <float name="fov" value="30"/>
    <transform name="to_world"><lookat origin="0, 0, 6" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/>
      <rfilter type="box"/></film>
  </sensor>
  <emitter type="point"><point name="position" x="1" y="1" z="3"/><rgb name="intensity" value="10"/></emitter>
  <shape type="rectangle">
    <bsdf type="mask"><float name="opacity" value="{opacity}"/>
      <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.5, 0.7"/></bsdf></bsdf>
  </shape>
</scene>"""


def test_mask_direct_light_is_linear_in_opacity(tmp_path):
    """A mask of opacity ``a`` over a diffuse quad, lit by a point light with nothing behind
    it (max_depth 2, no sky): the image is ``a`` times the opaque quad's, the mask's
    ``eval`` being ``a f`` whatever slot the vertex then samples (the pass-through or the
    diffuse lobe). Mitsuba's ``path`` keeps a path's radiance only once one of its vertices
    has sampled a non-null lobe or hit an emitter (``valid_ray``; where the scene has no
    environment), which drops the direct light of the vertices that sampled the
    pass-through: ``a^2`` times the opaque image (docs/performance.md, "Masks: Mitsuba's
    `valid_ray`"). With one seed both renders trace the same camera rays and the direct
    light of a point light is deterministic, so the ratio is ``a`` to rounding; the bound
    is 2%. Negative control: the quad rendered at opacity ``a^2`` (the image Mitsuba's rule
    gives at ``a``) fails the same check."""
    def total(opacity):
        (tmp_path / "m.xml").write_text(MASK_XML.format(opacity=opacity))
        r = Renderer(load_scene(tmp_path / "m.xml"),
                     RenderOptions(width=16, height=16, spp=16, seed=3, progress=False,
                                   path=PathOptions(max_depth=2)))
        return float(r.render().image.sum())

    opaque, a = total(1.0), 0.4
    assert opaque > 0.0

    def linear(ratio):
        return abs(ratio - a) < 0.02 * a

    assert linear(total(a) / opaque)
    assert not linear(total(a * a) / opaque)  # the negative control: Mitsuba's a^2
