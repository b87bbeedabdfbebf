"""Frozen camera passes (drpt/render/frozen.py): a pass traced once and replayed gives the
images a traced pass gives, bit for bit, for every seed and pass; what varies per render
enters as inputs (a control with the seed baked into the recording repeats its image);
changed options record again; Embree's queries replay."""

import dataclasses

import drjit as dr
import numpy as np
import pytest

from drpt.options import PathOptions, RenderOptions
from drpt.render import frozen
from drpt.render.renderer import Renderer
from drpt.scene import load_scene


def _renders(renderer, seeds, enabled):
    old = frozen.ENABLED
    frozen.ENABLED = enabled
    try:
        out = []
        for s in seeds:
            renderer.opt.seed = s
            out.append(renderer.render().image.copy())
        return out
    finally:
        frozen.ENABLED = old


def _recordings(renderer):
    return {name: f.recordings for name, f in renderer._frozen.items()}


OPTIONS = {
    # one pass of lanes per sample (squares multiplied in lane_sums), the inline BVH
    "lanes_inline": dict(width=24, height=18, spp=6, accel="inline"),
    # several passes (bands of rows and sample steps), path regeneration's longer lanes
    "passes": dict(width=24, height=18, spp=40, max_lanes=24 * 6 * 8, accel="inline"),
    # bands of 3, 3 and 2 rows: each pass shape its own recording (a dataclass argument
    # once hid the rows from the recordings' key, and a pass of 2 rows replayed one of 3)
    "uneven_bands": dict(width=12, height=8, spp=3, max_lanes=40, accel="inline"),
    # Embree's queries inside the recorded kernels (handles as inputs)
    "embree": dict(width=24, height=18, spp=6, accel="embree"),
    "ldsampler": dict(width=24, height=18, spp=8, sampler="ldsampler", accel="inline"),
    "zsobol_moment": dict(width=24, height=18, spp=8, sampler="zsobol", moment=True, accel="inline"),
    "gaussian_splat": dict(width=24, height=18, spp=4, filter="gaussian", accel="inline"),
}


@pytest.mark.parametrize("name", OPTIONS)
def test_replayed_passes_equal_traced_ones(cornell, name):
    if name == "embree":
        from drpt.accel import embree_lib

        if embree_lib.reason():
            pytest.skip(embree_lib.reason())
    r = Renderer(load_scene(cornell), RenderOptions(progress=False, **OPTIONS[name]))
    seeds = [3, 4, 5, 4]
    replayed = _renders(r, seeds, True)
    recs = _recordings(r)
    shapes = len({(k, rows) for _, k, _, rows in r.plan})
    assert recs and all(v == shapes for v in recs.values()), recs  # recorded once, then replayed
    assert all(f.failed is None for f in r._frozen.values())
    traced = _renders(r, seeds, False)
    for a, b in zip(replayed, traced):
        assert np.array_equal(a, b)
    assert not np.array_equal(replayed[1], replayed[2])  # the seeds' images differ
    assert np.array_equal(replayed[1], replayed[3])


def test_control_a_seed_baked_into_the_recording_repeats_its_image(cornell, monkeypatch):
    """The keys are what makes a replay follow the seed: made opaque inside the body (a
    value from Python state), the replay draws the recorded seed's numbers."""
    r = Renderer(load_scene(cornell), RenderOptions(progress=False, width=16, height=12, spp=4,
                                                    sampler="independent", accel="inline"))
    inner = r._pass_arrays

    def baked(keys, *args):
        from drpt.render.renderer import _mix_seed
        from drpt.render.sampler import pcg_keys
        return inner(keys | {"pcg": pcg_keys(_mix_seed(r.opt.seed, 0))}, *args)

    monkeypatch.setattr(r, "_pass_arrays", baked)
    a, b, c = _renders(r, [1, 2, 3], True)
    assert not np.array_equal(a, b)  # traced: the seed's own numbers
    assert np.array_equal(b, c)  # replayed: the recording's


def test_a_pass_that_cannot_be_recorded_is_traced(cornell, monkeypatch):
    """Dr.Jit 1.5 cannot record a body that uploads an array itself (``UInt32(list)``):
    the renderer then traces every pass, with the same images."""
    from drjit.auto import UInt32

    r = Renderer(load_scene(cornell), RenderOptions(progress=False, width=16, height=12, spp=4,
                                                    sampler="independent", accel="inline"))
    inner = r._pass_arrays

    def uploading(keys, *args):
        sums, sqsums, nbad = inner(keys, *args)
        return sums, sqsums, nbad + dr.gather(UInt32, UInt32([0, 0]), UInt32(0) * nbad)

    monkeypatch.setattr(r, "_pass_arrays", uploading)
    images = _renders(r, [1, 2, 3], True)
    assert r._frozen["pass"].failed.startswith("record()")
    for a, b in zip(images, _renders(r, [1, 2, 3], False)):
        assert np.array_equal(a, b)


def test_changed_options_record_again(cornell):
    r = Renderer(load_scene(cornell), RenderOptions(progress=False, width=16, height=12, spp=4,
                                                    accel="inline", path=PathOptions(max_depth=5)))
    _renders(r, [1, 2, 3], True)
    assert _recordings(r) == {"pass": 1}
    r.opt = dataclasses.replace(r.opt, path=PathOptions(max_depth=2))
    r.integrator = r._make_integrator()
    shallow = _renders(r, [1, 2], True)
    assert _recordings(r) == {"pass": 2}
    assert np.array_equal(shallow[1], _renders(r, [2], False)[0])


def test_derived_renderer_freezes_its_own_passes(cornell):
    r = Renderer(load_scene(cornell), RenderOptions(progress=False, width=16, height=12, spp=4,
                                                    accel="inline"))
    _renders(r, [1, 2, 3], True)
    d = r.derive(dataclasses.replace(r.opt, path=PathOptions(max_depth=1)))
    assert _recordings(d) == {}
    a = _renders(d, [1, 2, 3], True)
    assert np.array_equal(a[2], _renders(d, [3], False)[0])


def test_an_instrumented_render_traces_every_pass(cornell):
    """An instrument observes each trace (drpt.render.instrument): with one attached the
    passes are traced, and it sees every one."""
    from drpt.render.instrument import Instrument

    class Counting(Instrument):
        calls = 0

        def paths(self, lanes, kinds=()):
            Counting.calls += 1

    r = Renderer(load_scene(cornell), RenderOptions(progress=False, width=16, height=12, spp=4,
                                                    accel="inline"))
    r.scene.instrument = Counting()
    _renders(r, [1, 2, 3], True)
    assert Counting.calls == 3 and r._frozen == {}


def test_device_arrays_walks_attributes_containers_and_slots():
    from drjit.auto import Float, UInt32

    class Slotted:
        __slots__ = ("a", "b")

    class Plain:
        pass

    x, y, z = Float(1, 2), UInt32(3), Float(4)
    s = Slotted()
    s.a, s.b = x, [y, {"k": z, "n": np.zeros(3)}]
    p = Plain()
    p.s, p.again, p.number, p.kind = s, x, 5, Float
    p.cycle = p
    found = frozen.device_arrays(p)
    assert len(found) == 3 and {id(v) for v in found} == {id(x), id(y), id(z)}


def test_device_arrays_skips_tuples_of_host_values_on_later_walks():
    """With ``inert`` the walk remembers the tuples that hold host values only (nested too)
    and skips them later, with the same arrays found: a tuple holding an array is never
    remembered, and an array added to a list (mutable) is found by the next walk. Control: a
    tuple wrongly remembered hides its array, so the list compared is the walk's."""
    from drjit.auto import Float

    class Plain:
        pass

    x, y = Float(1, 2), Float(3)
    runs = ((1, 2.0, "a"), (3, (4.0, 5)), np.zeros(2))
    p = Plain()
    p.runs, p.mixed, p.rows = runs, (1, x), [(7, 8)]
    inert: dict = {}
    for _ in range(3):
        assert [id(v) for v in frozen.device_arrays(p, inert=inert)] == [id(x)]
    assert id(runs) in inert and id(runs[1]) in inert and id(p.mixed) not in inert
    p.rows.append((9, y))
    assert [id(v) for v in frozen.device_arrays(p, inert=inert)] == [id(x), id(y)]
    inert[id(p.mixed)] = p.mixed  # control
    assert [id(v) for v in frozen.device_arrays(p, inert=inert)] == [id(y)]


def test_device_arrays_does_not_enter_the_host_packages():
    """The walk does not enter objects of the host packages (``frozen.HOST_PACKAGES``: the
    scene model, the material specifications, the options), which it may do because no module
    of theirs imports Dr.Jit (read from their sources: an import added there fails this test).
    Control: an array put on such an object is not found, and the same array on a plain object
    is."""
    import ast
    import importlib
    import pkgutil

    from drjit.auto import Float

    from drpt.scene.model import Scene

    for name in frozen.HOST_PACKAGES:
        package = importlib.import_module(name)
        modules = [package.__file__]
        if hasattr(package, "__path__"):  # (a package: its modules too)
            modules += [importlib.util.find_spec(m.name).origin
                        for m in pkgutil.walk_packages(package.__path__, name + ".")]
            assert len(modules) > 1
        for path in modules:
            tree = ast.parse(open(path).read())
            imported = {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
            imported |= {(n.module or "").split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
            assert "drjit" not in imported, path

    class Plain:
        pass

    x = Float(1, 2)
    host = object.__new__(Scene)  # (its fields do not matter here)
    host.stray = x
    p = Plain()
    p.host = host
    assert frozen.device_arrays(p) == []
    p.plain = Plain()
    p.plain.stray = x
    assert [id(v) for v in frozen.device_arrays(p)] == [id(x)]


def test_freezes_only_megakernel_camera_passes(cornell, monkeypatch):
    monkeypatch.setattr(frozen, "ENABLED", True)
    scene = load_scene(cornell)
    for integrator, mode, expect in [("path", "megakernel", True), ("path", "wavefront", False),
                                     ("ptracer", "megakernel", False)]:
        r = Renderer(scene, RenderOptions(progress=False, width=8, height=8, spp=2,
                                          integrator=integrator, mode=mode))
        assert frozen.freezes(r.integrator) is expect
