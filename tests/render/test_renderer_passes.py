"""Pass planning and path regeneration (drpt/render/renderer.py): every (pixel, sample) exactly once,
never more than the lane budget at a time; the public per-pass API (``Renderer.render_pass``,
``PassPlan.at``) sums to the render and goes on past the plan's last pass."""

import numpy as np
import pytest

from drpt.render import film
from drpt.render.renderer import plan_passes


@pytest.mark.parametrize("w,h,spp,budget", [(1, 1, 1, 16), (7, 5, 33, 64), (100, 37, 3, 250),
                                            (64, 64, 256, 1 << 21), (3, 1, 5, 1)])
def test_passes_cover_once_within_budget(w, h, spp, budget):
    count = np.zeros((h, spp), int)
    for s0, k, r0, rows in plan_passes(w, h, spp, budget):
        assert rows * w * k <= max(budget, w)  # one row is the smallest unit
        count[r0:r0 + rows, s0:s0 + k] += 1
    assert np.all(count == 1)


@pytest.mark.parametrize("spp,max_lanes,min_lanes", [(13, 1 << 21, 100), (13, 70, 100),
                                                     (5, 1 << 21, 1), (64, 1 << 21, 1 << 14)])
def test_every_pixel_gets_exactly_spp_samples(tmp_path, monkeypatch, spp, max_lanes, min_lanes):
    """Path regeneration bookkeeping: with a constant sky and nothing in view
    every sample is exactly 0.5, so the image is 0.5 with zero variance only
    if each pixel's lanes together trace exactly ``spp`` samples, whatever the
    lanes per pixel (the policy's ``min_lanes``), the remainder split and the passes."""
    import dataclasses

    from drpt import backend
    from drpt.imageio import write_image
    from drpt.render import renderer
    from drpt.scene import load_scene

    policy = dataclasses.replace(backend.policy(), min_lanes=min_lanes)
    monkeypatch.setattr(renderer, "policy", lambda: policy)
    write_image(tmp_path / "sky.exr", np.full((4, 8, 3), 0.5, np.float32))
    (tmp_path / "s.txt").write_text(
        "PerspectiveCamera { center 0 0 0 direction 0 0 -1 up 0 1 0 angle 30 }\n"
        "Lights { numLights 1 Skybox { sky.exr } }\n"
        "Group { numObjects 1 Sphere { center 0 0 50 radius 1 } }\n")  # behind the camera
    r = renderer.Renderer(load_scene(tmp_path / "s.txt"), renderer.RenderOptions(
        width=7, height=5, spp=spp, max_lanes=max_lanes, progress=False)).render()
    assert r.samples == 7 * 5 * spp
    assert np.array_equal(r.image, np.full((5, 7, 3), 0.5, np.float32))
    assert np.all(r.variance == 0.0)


def test_plan_at_goes_on_past_the_last_pass():
    plan = plan_passes(10, 7, 3, 30)  # bands of 3 rows, one sample per pixel per pass
    assert [plan.at(i) for i in range(plan.count)] == list(plan)
    longer = plan_passes(10, 7, 5, 30)
    assert [plan.at(i) for i in range(longer.count)] == list(longer)
    with pytest.raises(IndexError):
        plan[plan.count]


def test_render_passes_sum_to_the_render(cornell):
    """``render`` is the plan's passes in order, summed (float64) over spp: the same bits.
    Past the plan, pass ``i`` is the longer render's pass ``i`` (a live view's next frame).
    Negative control: another pass index gives other sums."""
    from dataclasses import replace

    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer
    from drpt.scene import load_scene

    r = Renderer(load_scene(cornell), RenderOptions(width=8, height=6, spp=3, seed=2, max_lanes=16,
                                                    progress=False))
    assert r.plan.bands == 3 and r.plan.count == 9
    acc = np.zeros((6, 8, 3))
    for i in range(r.plan.count):
        p = r.render_pass(i)
        acc[p.lo:p.lo + p.sum.shape[0]] += p.sum
    assert np.array_equal((acc / 3).astype(np.float32), r.render().image)
    longer = r.derive(replace(r.opt, spp=4))
    past = r.render_pass(10)
    assert past.lo == 2 and np.array_equal(past.sum, longer.render_pass(10).sum)
    assert not np.array_equal(past.sum, r.render_pass(7).sum)  # same rows, another sample step


@pytest.mark.parametrize("chunk_spp,max_lanes", [(None, 1 << 20), (2, 1 << 20), (2, 40)])
def test_splatted_chunks_added_into_the_merge_are_the_merged_chunks(cornell, chunk_spp, max_lanes):
    """A splatting render (Gaussian filter, the moment integrator's products) adds a chunk of
    one pass straight into its merge (``render_chunk(into=...)``, :attr:`ChunkResult.direct`):
    the same sums, squares and weights, bit for bit, as the chunks' own arrays merged
    (``render_chunk`` without ``into``), and the render's image is theirs; a chunk of several
    passes (bands of rows, ``max_lanes`` 40) keeps its own arrays. Negative control: the
    chunks of another seed, merged, give other weights and sums."""
    from dataclasses import replace

    from drpt.options import RenderOptions
    from drpt.render.chunks import ChunkMerge
    from drpt.render.renderer import Renderer, finish
    from drpt.scene import load_scene

    r = Renderer(load_scene(cornell), RenderOptions(
        width=9, height=7, spp=4, seed=3, max_lanes=max_lanes, chunk_spp=chunk_spp, moment=True,
        filter="gaussian", progress=False))
    assert r.splatting and r.chunks.count == (2 if chunk_spp else 1)
    one_pass = len(r.chunks.passes_of(0)) == 1
    assert one_pass == (max_lanes > 40)

    def merged(renderer, into: bool) -> ChunkMerge:
        m = ChunkMerge(renderer.chunks)
        for c in range(renderer.chunks.count):
            result = renderer.render_chunk(c, into=m if into else None)
            assert result.direct == (into and one_pass)
            m.push(result)
        return m

    apart, direct = merged(r, False), merged(r, True)
    arrays = lambda m: (m.sum, m.sumsq, m.weight)  # noqa: E731
    assert direct.sumsq.shape == (7, 9, 9)
    assert all(np.array_equal(a, b) for a, b in zip(arrays(apart), arrays(direct)))
    assert np.array_equal(finish(apart, 0.0, 0.0).image, r.render().image)
    other = merged(r.derive(replace(r.opt, seed=4)), True)
    assert not any(np.array_equal(a, b) for a, b in zip(arrays(other), arrays(direct)))



def test_a_splatting_merge_takes_its_first_pass_sums(cornell):
    """A splatting render of one chunk of one pass: the merge takes the pass's float64 arrays as
    its sums (no additions into its zeros: ``0.0 + x`` is ``x`` bit for bit, the gathered sums
    starting from +0.0 are never -0.0), and the image is that of the chunk's own arrays merged
    (the test above compares the sums); ``_takes`` refuses a pass that does not cover the
    image, float32 sums, read-only ones and other shapes. Negative control: ``0.0 + -0.0`` is
    +0.0, the one value whose bits a taken array would not share with the sum."""
    from drpt.options import RenderOptions
    from drpt.render import renderer
    from drpt.render.chunks import ChunkMerge
    from drpt.scene import load_scene

    r = renderer.Renderer(load_scene(cornell), RenderOptions(
        width=9, height=7, spp=4, seed=3, moment=True, filter="gaussian", progress=False))
    m = ChunkMerge(r.chunks)
    zeros = m.sum
    m.push(r.render_chunk(0, into=m))
    assert m.sum is not zeros and not m.sum.flags.owndata and m.sum.dtype == np.float64
    apart = ChunkMerge(r.chunks)
    apart.push(r.render_chunk(0))
    assert all(np.array_equal(a, b) for a, b in zip((m.sum, m.sumsq, m.weight),
                                                    (apart.sum, apart.sumsq, apart.weight)))
    fresh = ChunkMerge(r.chunks)
    fresh.sumsq, fresh.weight = np.zeros((7, 9, 9)), np.zeros((7, 9, 2))
    p = renderer.PassSums(0, m.sum, m.sumsq, 0, m.weight)
    assert renderer._takes(fresh, p)
    assert not renderer._takes(fresh, renderer.PassSums(1, m.sum, m.sumsq, 0, m.weight))
    assert not renderer._takes(fresh, renderer.PassSums(0, m.sum.astype(np.float32), m.sumsq, 0, m.weight))
    frozen = m.sum.copy()
    frozen.flags.writeable = False
    assert not renderer._takes(fresh, renderer.PassSums(0, frozen, m.sumsq, 0, m.weight))
    assert not renderer._takes(fresh, renderer.PassSums(0, m.sum, m.sumsq[..., :3], 0, m.weight))
    assert np.signbit(np.float64(-0.0)) and not np.signbit(np.float64(0.0) + np.float64(-0.0))


def test_a_box_merge_makes_its_first_whole_image_pass_its_sums(cornell):
    """A box render of one chunk of one pass (the moment integrator's products too): the merge's
    sums are new float64 arrays of ``0.0 + x`` of the pass's float32 sums, not additions into
    its zeros, and equal, bit for bit, the chunk's own arrays merged; with bands of rows (passes
    of part of the image, chunks of a sample each) the additions go into the zeros as before.
    ``0.0 + x`` in float64 is the additions' value for every float32 ``x``, -0.0 (made +0.0),
    infinities and NaN included, also in the merge of a pass that holds them. Negative
    control: a plain float64 copy keeps -0.0's sign, which the sums merged into zeros do not."""
    from drpt.options import RenderOptions
    from drpt.render import renderer
    from drpt.render.chunks import ChunkMerge
    from drpt.scene import load_scene

    for max_lanes in (1 << 20, 40):
        r = renderer.Renderer(load_scene(cornell), RenderOptions(
            width=9, height=7, spp=4, seed=3, moment=True, max_lanes=max_lanes, progress=False))
        assert not r.splatting and (r.chunks.count == 1) == (max_lanes > 40)
        m, apart = ChunkMerge(r.chunks), ChunkMerge(r.chunks)
        zeros = m.sum
        for c in range(r.chunks.count):
            m.push(r.render_chunk(c, into=m))
            apart.push(r.render_chunk(c))
        assert (m.sum is zeros) == (max_lanes == 40) and m.sum.dtype == np.float64
        assert np.array_equal(m.sum, apart.sum) and np.array_equal(m.sumsq, apart.sumsq)
        assert m.sumsq.shape == (7, 9, 6)
    x = np.array([-0.0, 0.0, 1.5, -3e38, np.inf, -np.inf, np.nan, 1e-45], np.float32)
    into_zeros = np.zeros(x.shape) + x
    made = np.add(x, 0.0, dtype=np.float64)
    assert made.tobytes() == into_zeros.tobytes()
    assert x.astype(np.float64).tobytes() != into_zeros.tobytes()  # control
    # the renderer's own merge of a whole-image float32 pass holding -0.0: the zeros' bits
    r = renderer.Renderer(load_scene(cornell), RenderOptions(width=4, height=2, spp=1, moment=True, progress=False))
    sums = np.resize(x[:6], (2, 4, 3)).astype(np.float32)
    squares = np.resize(x, (2, 4, 6)).astype(np.float32)
    r.render_pass = lambda i: renderer.PassSums(0, sums, squares, 0)
    m = ChunkMerge(r.chunks)
    m.push(r.render_chunk(0, into=m))
    assert m.sum.tobytes() == (np.zeros((2, 4, 3)) + sums).tobytes()
    assert m.sumsq.tobytes() == (np.zeros((2, 4, 6)) + squares).tobytes()

def test_read_sums_of_a_whole_image_are_a_merges_additions_into_zeros():
    """``_read_sums`` of a whole image: one float64 ``(rows, W, C)`` array whose bits are the
    merge's additions of the float32 sums into its zeros (-0.0 made +0.0, infinities and NaN
    kept), which an empty merge may therefore take as its own; of a band of rows: the device's
    float32 values as they are (the merge adds them). Control: a plain float64 copy keeps
    -0.0's sign, which the additions into zeros do not."""
    from drjit.auto import Float

    from drpt.render.renderer import _read_sums

    x = np.array([-0.0, 0.0, 1.5, -3e38, np.inf, -np.inf, np.nan, 1e-45], np.float32)
    cols = [x, x[::-1].copy(), np.roll(x, 3)]
    whole = _read_sums([Float(c) for c in cols], 2, 4, True)
    into_zeros = np.zeros((8, 3)) + np.stack(cols, -1)
    assert whole.shape == (2, 4, 3) and whole.dtype == np.float64
    assert whole.tobytes() == into_zeros.reshape(2, 4, 3).tobytes()
    band = _read_sums([Float(c) for c in cols], 2, 4, False)
    assert band.dtype == np.float32 and band.tobytes() == np.stack(cols, -1).reshape(2, 4, 3).tobytes()
    assert np.stack(cols, -1).astype(np.float64).tobytes() != into_zeros.tobytes()  # control


def test_a_merge_makes_its_zeros_only_where_read(cornell, monkeypatch):
    """A merge's sums are zeros made where first read (``ChunkMerge.zeros``): a box render whose
    one whole-image pass the merge takes as its sums makes no image-sized zeros (``np.zeros`` of
    memory the heap reuses writes every byte), and an unmade sum reads as zeros of its shape.
    Control: a render of bands of rows adds into the zeros, which it makes."""
    from drpt.options import RenderOptions
    from drpt.render import renderer
    from drpt.render.chunks import ChunkMerge
    from drpt.scene import load_scene

    made = []
    zeros = np.zeros

    def counting(shape, *a, **kw):
        made.append(tuple(np.atleast_1d(shape)))
        return zeros(shape, *a, **kw)

    for max_lanes, expect in ((1 << 20, []), (40, [(7, 9, 3), (7, 9, 6)])):
        r = renderer.Renderer(load_scene(cornell), RenderOptions(
            width=9, height=7, spp=4, seed=3, moment=True, max_lanes=max_lanes, progress=False))
        m = ChunkMerge(r.chunks)
        assert m.shape_of("sum") == (7, 9, 3) and m.shape_of("sumsq") == (7, 9, 3)
        made.clear()
        monkeypatch.setattr(np, "zeros", counting)
        m.push(r.render_chunk(0, into=m))
        monkeypatch.setattr(np, "zeros", zeros)
        assert sorted(s for s in made if len(s) == 3) == expect, made
    m = ChunkMerge(r.chunks)
    m.zeros("sumsq", (7, 9, 6))
    assert m.shape_of("sumsq") == (7, 9, 6)
    assert m.sumsq.shape == (7, 9, 6) and m.sumsq.dtype == np.float64 and not m.sumsq.any()
    assert m.sumsq is m.sumsq  # (made once)


def test_xyz_second_moment_is_the_square_of_each_samples_xyz():
    """From the products ``(r^2, g^2, b^2, rg, rb, gb)`` of one sample the XYZ second moment
    is ``(A rgb)^2`` for each sample, and means of several samples are the mean of those.
    Negative control: the products in another order give another answer."""
    from drpt.render.renderer import SRGB_TO_XYZ, xyz_second_moment

    rgb = np.random.default_rng(1).random((4, 5, 3))
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    m = np.stack([r * r, g * g, b * b, r * g, r * b, g * b], -1)
    want = (rgb @ SRGB_TO_XYZ.T) ** 2
    assert np.allclose(xyz_second_moment(m), want, rtol=1e-12)
    assert np.allclose(xyz_second_moment(m.mean((0, 1))), want.mean((0, 1)), rtol=1e-12)
    assert not np.allclose(xyz_second_moment(m[..., [0, 1, 2, 5, 4, 3]]), want, rtol=1e-3)


def _record_lane_widths(monkeypatch, paths: list | None = None) -> list:
    """The lane count of every ``PathIntegrator.sample_sequence`` traced from now on (the
    method wrapped for the test), in order; with ``paths``, each call's total of its lanes'
    path counts appended to it."""
    import drjit as dr
    from drjit.auto import UInt32

    from drpt.render.integrators.path import PathIntegrator

    widths = []
    traced = PathIntegrator.sample_sequence

    def recording(self, rng, camera_ray, count, *args, **kw):
        widths.append(dr.width(count))
        if paths is not None:
            paths.append(int(dr.sum(UInt32(count)).numpy()[0]))
        return traced(self, rng, camera_ray, count, *args, **kw)

    monkeypatch.setattr(PathIntegrator, "sample_sequence", recording)
    return widths


MIRROR_XML = """<scene version="3.0.0">
  <integrator type="path"><integer name="max_depth" value="8"/></integrator>
  <sensor type="perspective">
    <transform name="to_world"><lookat origin="0, 0, -4" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="7"/><integer name="height" value="5"/>
      <rfilter type="box"/></film>
  </sensor>
  <emitter type="constant"><rgb name="radiance" value="0.5"/></emitter>
  <shape type="sphere"><bsdf type="{bsdf}"/></shape>
</scene>"""


def _two_spheres(bsdf: str) -> str:
    """:data:`MIRROR_XML` with two spheres of ``bsdf`` side by side, facing each other."""
    return MIRROR_XML.format(bsdf=bsdf).replace(
        '<shape type="sphere">', '<shape type="sphere"><point name="center" x="0.9" y="0" z="0"/>'
    ).replace('</scene>', '<shape type="sphere"><point name="center" x="-1.1" y="0" z="0"/>'
              f'<bsdf type="{bsdf}"/></shape></scene>')


@pytest.mark.parametrize("bsdf,per_sample", [("conductor", True), ("diffuse", False)])
def test_a_mirror_only_scene_traces_a_lane_per_sample(tmp_path, monkeypatch, bsdf, per_sample):
    """Where no BSDF is smooth (``PathIntegrator.pixel_coherent``) a pixel's samples each get
    a lane (a packet follows one pixel's mirror paths), whatever ``min_lanes`` asks, and the
    rays to ``COHERENT_DEPTH`` (the camera's and the first bounce's) ask for coherent
    traversal; a diffuse scene (the negative control) keeps ``min_lanes``' one lane per pixel
    here and coherence for camera rays only. Both trace every sample once."""
    import dataclasses

    from drpt import backend
    from drpt.render import renderer
    from drpt.render.scene import DeviceScene
    from drpt.scene import load_scene

    policy = dataclasses.replace(backend.policy(), min_lanes=1)
    monkeypatch.setattr(renderer, "policy", lambda: policy)
    widths = _record_lane_widths(monkeypatch)
    coherent = []
    query = DeviceScene.intersect_preliminary

    def asking(self, o, d, active, *args, **kw):
        coherent.append(kw.get("coherent", False))
        return query(self, o, d, active, *args, **kw)

    monkeypatch.setattr(DeviceScene, "intersect_preliminary", asking)
    (tmp_path / "s.xml").write_text(MIRROR_XML.format(bsdf=bsdf))
    spp = 6
    rend = renderer.Renderer(load_scene(tmp_path / "s.xml"), renderer.RenderOptions(
        width=7, height=5, spp=spp, progress=False))
    assert rend.integrator.pixel_coherent == per_sample
    r = rend.render()
    # (the pixels' lanes, padded to whole records where film.lane_sums reads records)
    assert widths == [film.pass_lanes(7 * 5, spp if per_sample else 1)]
    assert coherent and all(c is not False for c in coherent), coherent
    from drjit.auto import UInt32

    from drpt.render.integrators import path
    rule = rend.integrator.coherent_queries(UInt32(0, 1, 2, 3)).numpy().tolist()
    assert path.COHERENT_DEPTH == 1
    assert rule == ([True, True, False, False] if per_sample else [True, False, False, False])
    assert r.samples == 7 * 5 * spp
    assert np.all(np.isfinite(r.image)) and r.image.max() > 0.0


def test_coherent_queries_change_no_pixel_of_a_mirror_scene(tmp_path, monkeypatch):
    """``pixel_coherent``'s coherent traversal is a hint to Embree: the same hits, so a mirror
    scene's image is bit-identical with every query incoherent, and with every query coherent
    (the same random numbers are drawn either way). The spheres face each other, so paths
    bounce between them."""
    from drpt.accel import embree_lib
    from drpt.render import renderer
    from drpt.render.scene import DeviceScene
    from drpt.scene import load_scene

    if embree_lib.reason() is not None:
        pytest.skip(f"Embree unavailable: {embree_lib.reason()}")
    (tmp_path / "s.xml").write_text(_two_spheres("conductor"))
    scene = load_scene(tmp_path / "s.xml")

    def image():
        return renderer.Renderer(scene, renderer.RenderOptions(width=7, height=5, spp=8, accel="embree",
                                                               progress=False)).render().image

    coherent = image()
    query = DeviceScene.intersect_preliminary
    asked = []

    def incoherent(self, o, d, active, *args, **kw):
        asked.append(kw.pop("coherent", False))
        return query(self, o, d, active, *args, coherent=False, **kw)

    monkeypatch.setattr(DeviceScene, "intersect_preliminary", incoherent)
    plain = image()
    assert asked and all(c is not False for c in asked)
    assert coherent.max() > 0.0
    np.testing.assert_array_equal(plain, coherent)
    monkeypatch.undo()
    from drpt.render.integrators import path
    monkeypatch.setattr(path, "COHERENT_DEPTH", 100)
    np.testing.assert_array_equal(image(), coherent)


SKY_XML = """<scene version="3.0.0">
  <sensor type="perspective">
    <transform name="to_world"><lookat origin="0, 0, 0" target="0, 0, 1" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="7"/><integer name="height" value="5"/>
      <rfilter type="box"/></film>
  </sensor>
  <emitter type="constant"><rgb name="radiance" value="0.5"/></emitter>
  <shape type="sphere"><point name="center" x="0" y="0" z="-50"/><bsdf type="diffuse"/></shape>
</scene>"""


@pytest.mark.parametrize("depth,spp", [(2, 1), (2, 3), (2, 4), (3, 13), (8, 13)])
def test_unrolled_paths_trace_a_few_paths_per_lane(tmp_path, monkeypatch, depth, spp):
    """Short paths traced unrolled (``PathIntegrator.straight``) get ``ceil(spp / 3)`` lanes per
    pixel (:data:`~drpt.render.renderer.STRAIGHT_PATHS_PER_LANE`), whatever ``min_lanes`` asks,
    and every pixel still sums exactly ``spp`` samples (a constant sky, nothing in view: 0.5 and
    zero variance only then). Negative control: the bounce loop (depth 8) keeps ``min_lanes``'
    one lane per pixel."""
    import dataclasses

    from drpt import backend
    from drpt.options import PathOptions
    from drpt.render import renderer
    from drpt.scene import load_scene

    policy = dataclasses.replace(backend.policy(), min_lanes=1)
    monkeypatch.setattr(renderer, "policy", lambda: policy)
    paths = []
    widths = _record_lane_widths(monkeypatch, paths)
    (tmp_path / "s.xml").write_text(SKY_XML)
    rend = renderer.Renderer(load_scene(tmp_path / "s.xml"), renderer.RenderOptions(
        width=7, height=5, spp=spp, progress=False, path=PathOptions(max_depth=depth)))
    assert rend.integrator.straight == (depth <= 3)
    r = rend.render()
    per_pixel = -(-spp // renderer.STRAIGHT_PATHS_PER_LANE) if depth <= 3 else 1
    # (padded to whole records: the lanes past the pixels' trace no path, and add nothing to
    # the exact 0.5 below)
    assert widths == [film.pass_lanes(7 * 5, per_pixel)] and paths == [7 * 5 * spp]
    assert r.samples == 7 * 5 * spp
    assert np.array_equal(r.image, np.full((5, 7, 3), 0.5, np.float32))
    assert np.all(r.variance == 0.0)


@pytest.mark.parametrize("accel,lanes_rule,per_sample", [
    ("bvh", True, True), ("grid", True, True), ("embree", True, True),
    ("inline", True, False), ("bvh", False, False)])
def test_a_tree_accelerator_traces_a_lane_per_sample(tmp_path, monkeypatch, accel, lanes_rule, per_sample):
    """On an accelerator that traverses a tree or grid (``coherent_gain``), where the backend's
    policy says ``sample_lanes``, the bounce loop's samples each get a lane (a packet's camera
    rays are then one pixel's), whatever ``min_lanes`` asks; every pixel still sums exactly
    ``spp`` samples (a constant sky, nothing in view: 0.5 and zero variance only then).
    Negative controls: the inline list (every ray costs the same) and a policy without
    ``sample_lanes`` keep ``min_lanes``' one lane per pixel."""
    import dataclasses

    from drpt import backend
    from drpt.accel import embree_lib
    from drpt.options import PathOptions
    from drpt.render import renderer
    from drpt.scene import load_scene

    if accel == "embree" and embree_lib.reason() is not None:
        pytest.skip(f"Embree unavailable: {embree_lib.reason()}")
    policy = dataclasses.replace(backend.policy(), min_lanes=1, sample_lanes=lanes_rule)
    monkeypatch.setattr(renderer, "policy", lambda: policy)
    paths = []
    widths = _record_lane_widths(monkeypatch, paths)
    (tmp_path / "s.xml").write_text(SKY_XML)
    spp = 13
    rend = renderer.Renderer(load_scene(tmp_path / "s.xml"), renderer.RenderOptions(
        width=7, height=5, spp=spp, progress=False, accel=accel, path=PathOptions(max_depth=8)))
    assert not rend.integrator.straight and not rend.integrator.pixel_coherent
    assert rend.scene.accel.coherent_gain == (accel != "inline")
    r = rend.render()
    assert widths == [film.pass_lanes(7 * 5, spp if per_sample else 1)] and paths == [7 * 5 * spp]
    assert r.samples == 7 * 5 * spp
    assert np.array_equal(r.image, np.full((5, 7, 3), 0.5, np.float32))
    assert np.all(r.variance == 0.0)


def test_a_lane_per_sample_traces_the_loop_without_restarts(tmp_path, monkeypatch):
    """Where each lane traces one sample (a tree accelerator), the bounce loop is traced
    without the code that starts a lane's next path (``PathIntegrator._loop_single``), and
    the image, variance and sample count are those of the regenerating loop given one path a
    lane, bit for bit (two diffuse spheres side by side under a constant sky, paths to depth
    8, some bouncing between the spheres). Control: the
    inline list with ``min_lanes`` 1 regenerates paths and does not call it."""
    import dataclasses

    import drjit as dr

    from drpt import backend
    from drpt.options import PathOptions
    from drpt.render import renderer
    from drpt.render.integrators.path import PathIntegrator
    from drpt.scene import load_scene

    (tmp_path / "s.xml").write_text(_two_spheres("diffuse"))
    scene = load_scene(tmp_path / "s.xml")
    single = PathIntegrator._loop_single
    calls = []

    def spy(self, *args):
        calls.append(dr.width(args[2]))
        return single(self, *args)

    def render(accel):
        return renderer.Renderer(scene, renderer.RenderOptions(
            width=7, height=5, spp=6, progress=False, accel=accel, path=PathOptions(max_depth=8))).render()

    policy = dataclasses.replace(backend.policy(), min_lanes=1)
    monkeypatch.setattr(renderer, "policy", lambda: policy)
    monkeypatch.setattr(PathIntegrator, "_loop_single", spy)
    inline = render("inline")
    assert calls == []
    fast = render("bvh")
    assert calls == [film.pass_lanes(7 * 5, 6)]
    monkeypatch.setattr(PathIntegrator, "_loop_single", PathIntegrator._loop_sequence)
    plain = render("bvh")
    assert fast.samples == plain.samples == inline.samples == 7 * 5 * 6
    assert fast.image.max() > 0.0 and fast.image.min() < fast.image.max()
    np.testing.assert_array_equal(fast.image, plain.image)
    np.testing.assert_array_equal(fast.variance, plain.variance)
