"""DeviceScene.restricted (drpt/render/scene.py): a view for some material kinds, with
its feature flags recomputed in the one place they are defined.

On the mixed-material Cornell box (principled, rough and smooth dielectrics,
diffuse): a view of the smooth dielectric alone (a delta lobe) has no smooth BSDF,
so it traces no next-event estimation, while views of smooth kinds and the whole
scene have one; the emitter flags are the scene's; the view shares the device data
and leaves the scene as it was (negative control: the whole scene's flag stays on).
A view traces only its kinds' lobes (the wavefront's queues: their kernels).

``eval_emitter``'s symbolic ``if`` (on the lanes that hit a light or escaped to a sky)
gives the lookups' own values on every lane (Veach's scene, an environment map).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drpt.accel import InlineList
from drpt.options import RenderOptions
from drpt.render.scene import DeviceScene, EmissiveList, emissive_inline
from drpt.scene import load_scene
from drpt.scene import model as M

FLAGS = ("has_area_lights", "has_delta_lights", "has_environment", "has_background", "has_ambient")


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    from drpt.tools.scenegen import materials_cornell

    out = tmp_path_factory.mktemp("restricted")
    materials_cornell.main(out)
    return DeviceScene(load_scene(out / "materials_cornell.txt"), RenderOptions(width=8, height=8, spp=1))


def test_flags_of_a_view_follow_its_kinds(scene):
    kinds = scene.materials.kinds
    assert "dielectric" in kinds and "diffuse" in kinds, kinds
    assert scene.has_smooth_bsdfs
    glass = scene.restricted(("dielectric",))
    assert not glass.has_smooth_bsdfs  # delta lobes only: no next-event estimation
    assert glass.materials.is_specular_only()
    for k in kinds:
        view = scene.restricted((k,))
        assert view.has_smooth_bsdfs == (not scene.materials.lobes[k].DELTA), k
        assert all(getattr(view, f) == getattr(scene, f) for f in FLAGS)
    assert scene.restricted(("dielectric", "diffuse")).has_smooth_bsdfs


def test_a_view_shares_the_device_data_and_leaves_the_scene(scene):
    view = scene.restricted(("dielectric",))
    assert view.accel is scene.accel and view.surfaces is scene.surfaces
    assert view.area_lights is scene.area_lights and view.environment is scene.environment
    assert view.materials is not scene.materials
    assert view.materials._data is scene.materials._data  # nothing uploaded again
    assert scene.has_smooth_bsdfs and not scene.materials.is_specular_only()


def test_a_view_traces_only_its_lobes(scene, monkeypatch):
    import drjit as dr
    from drjit.auto import Array2f, Array3f, Bool, Float, UInt32

    from drpt.render.surface import Interaction

    table = scene.materials
    traced = []
    for kind, mod in table.lobes.items():
        orig = mod.sample

        def spy(*a, _orig=orig, _kind=kind, **k):
            traced.append(_kind)
            return _orig(*a, **k)

        monkeypatch.setattr(mod, "sample", spy)
    n = 4
    z = dr.full(Array3f, [0.0, 0.0, 1.0], n)
    # (the material ids opaque, as a render's: a literal id selects one kind at trace time)
    si = Interaction(dr.full(Bool, True, n), dr.full(Float, 1.0, n), dr.zeros(Array3f, n), z, z,
                     dr.zeros(UInt32, n), dr.opaque(UInt32, 0, n), z)
    for kinds in (("dielectric",), ("diffuse",)):
        traced.clear()
        scene.restricted(kinds).sample_bsdf(si, dr.full(Float, 0.5, n), dr.full(Array2f, 0.5, n))
        assert traced == list(kinds)
    traced.clear()
    scene.sample_bsdf(si, dr.full(Float, 0.5, n), dr.full(Array2f, 0.5, n))
    assert sorted(traced) == sorted(table.kinds)  # the whole scene traces every kind


# ------------------------------------------------------------------ eval_emitter's branch
XML = Path(__file__).parents[1] / "data" / "xml"


@pytest.mark.parametrize("name", ["veach_mis.xml", "envmap.xml"])
def test_eval_emitter_branch_gives_the_lookups_values(name, monkeypatch):
    """:meth:`DeviceScene.eval_emitter` runs its lookups in a symbolic ``if`` on the lanes
    that hit an emissive surface or escaped (to a sky); its radiance and density equal the
    lookups' own on every lane (Veach's scene: sphere and rectangle lights, escaping rays
    that see nothing; ``envmap.xml``: a sky). Rays from points around the scene toward its
    lights and every other way; some hit a light, some escape. Negative control: with no
    lane in the branch (``sees`` forced off), the values are 0 where the lookups' are not."""
    import numpy as np
    from drjit.auto import Array3f, Bool, Float

    scene = DeviceScene(load_scene(XML / name), RenderOptions(width=8, height=8, spp=1))
    rng = np.random.default_rng(3)
    n = 4096
    o = rng.uniform(-3, 3, (3, n)).astype(np.float32)
    o[1] = np.abs(o[1])
    targets = np.array([[-3.75, 0.2, -0.5], [-1.25, 0.2, -0.5], [1.25, 0.2, -0.5], [3.75, 0.2, -0.5],
                        [0.0, 8.0, 2.0]], np.float32).T
    d = np.where(rng.random(n) < 0.5, targets[:, rng.integers(0, 5, n)] - o, rng.normal(size=(3, n)))
    d = (d / np.linalg.norm(d, axis=0)).astype(np.float32)
    O, D = Array3f(*(Float(x) for x in o)), Array3f(*(Float(x) for x in d))
    active = Bool(rng.random(n) < 0.9)
    si = scene.intersect(O, D, active)
    le, pdf = scene.eval_emitter(si, D, active)
    hit, escaped = active & si.valid, active & ~si.valid
    le0, pdf0 = scene._eval_emitter(si, D, hit, escaped, True, True)
    le, pdf, le0, pdf0 = (np.array(v) for v in (le, pdf, le0, pdf0))
    assert (le0.max(0) > 0).sum() > 50 and (pdf0 > 0).sum() > 50  # lights were reached
    assert np.array(escaped).sum() > 50
    np.testing.assert_array_equal(le, le0)
    np.testing.assert_array_equal(pdf, pdf0)
    # negative control: the branch decides which lanes get values (none here)
    monkeypatch.setattr(scene.materials, "is_emissive", lambda si, active: Bool(False) & active)
    monkeypatch.setattr(scene, "has_background", False)
    for f in scene.emitter_selection.families:
        monkeypatch.setattr(f, "infinite", False)
    le1, pdf1 = (np.array(v) for v in scene.eval_emitter(si, D, active))
    assert np.all(pdf1 == 0) and np.all(le1 == 0) and not np.array_equal(pdf1, pdf0)


def test_eval_emitter_branches_only_where_the_lookups_cost_more():
    """The symbolic ``if`` is traced for emissive spheres (Veach's scene) and not for
    constant emission on triangles with a static selection (the Cornell box), whose path
    kernel it made slower; the negative control is the Veach scene itself."""
    root = Path(__file__).resolve().parents[2]
    opts = RenderOptions(width=8, height=8, spp=1, progress=False)
    cornell = DeviceScene(load_scene(root / "scenes" / "cornellbox" / "cornellbox.txt"), opts)
    veach = DeviceScene(load_scene(root / "tests" / "data" / "xml" / "veach_mis.xml"), opts)
    assert not cornell._costly_emitter_lookups()
    assert veach._costly_emitter_lookups()


def _ceiling_with_light(gap: float):
    """A ceiling (z = 2, eight triangles around a hole) with a light rectangle in the hole,
    ``gap`` below the ceiling's plane, sharing no edge with it."""
    def rect(x0, y0, x1, y1, z):
        c = np.float64([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]])
        return [c[[0, 1, 2]], c[[2, 3, 0]]]

    ceiling = (rect(-2, -2, 2, -1, 2) + rect(-2, 1, 2, 2, 2) + rect(-2, -1, -1, 1, 2)
               + rect(1, -1, 2, 1, 2))
    light = rect(-0.5, -0.5, 0.5, 0.5, 2 - gap)
    tris = np.stack(ceiling + light)
    mats = np.int32([0] * len(ceiling) + [1] * len(light))
    cam = M.PerspectiveCamera((0, 0, 0), (0, 0, 1), (0, 1, 0), 40.0)
    return M.Scene(path=None, camera=cam, triangles=M.Triangles(tris, mats),
                   materials=[M.Material("wall"), M.Material("light", emission=(1.0, 1.0, 1.0))])


def test_emissive_list_leaves_a_light_set_into_a_coplanar_ceiling_unpaired():
    """The emissive list (an inline accelerator of the emissive triangles alone) tests a
    light rectangle as one parallelogram only where, as in the scene's own accelerator, no
    other surface of the scene touches its plane: a light set flush into a ceiling stays two
    triangles in both. Negative control: lowered 1e-3 below the ceiling, it is paired in
    both; and the list built without the rest of the scene pairs the flush one."""
    for gap, pairs in ((0.0, 0), (1e-3, 1)):
        scene = _ceiling_with_light(gap)
        em = emissive_inline(scene)
        assert em is not None and em.count == 2
        assert len(em._list.quads) == pairs
        assert sum(q.first >= 8 for q in InlineList(scene).quads.values()) == pairs
    flush = _ceiling_with_light(0.0)
    alone = EmissiveList(em._ids.numpy(), flush.triangles.positions[8:])
    assert len(alone._list.quads) == 1
