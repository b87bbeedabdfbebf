"""The material table (drpt/render/material.py): trees flattened into weighted
components, sidedness, textured fields, and the mixture's eval/pdf/sample
against Mitsuba's own ``blendbsdf`` and ``mask``."""

from __future__ import annotations

from pathlib import Path

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array2f, Array3f, Bool, Float, UInt32

from drpt.errors import Loc, SceneError
from drpt.export.mitsuba_bsdf import to_mitsuba
from drpt.materials.layout import flatten
from drpt.materials.spec import BSDFSpec, Texture, complete
from drpt.render.material import MaterialTable
from drpt.render.surface import Interaction
from drpt.scene.model import Background, Material, PerspectiveCamera, Planes, Scene, Spheres, Triangles
from drpt.testing import mitsuba, to_mitsuba_vec3


def two(spec):
    return BSDFSpec("twosided", children=[spec])


def diffuse(c=(0.5, 0.5, 0.5)):
    return BSDFSpec("diffuse", {"kd": c})


def scene_with(*specs):
    cam = PerspectiveCamera((0, 0, 5), (0, 0, -1), (0, 1, 0), 40.0)
    mats = [Material(f"m{i}", bsdf=s) for i, s in enumerate(specs)]
    pos = np.array([[[-1.0, -1, 0], [1, -1, 0], [1, 1, 0]]] * len(specs))
    uvs = np.zeros((len(specs), 3, 2))
    return Scene(Path("t.txt"), cam, mats, Triangles(pos, np.arange(len(specs), dtype=np.int32), uvs=uvs),
                 Spheres.empty(), Planes.empty(), [], Background())


def interaction(wi: np.ndarray, material: int) -> Interaction:
    n = wi.shape[1]
    z = Array3f(dr.full(Float, 0.0, n), dr.full(Float, 0.0, n), dr.full(Float, 1.0, n))
    return Interaction(dr.full(Bool, True, n), dr.full(Float, 1.0, n), dr.zeros(Array3f, n), z, z,
                       dr.zeros(UInt32, n), dr.full(UInt32, material, n), to_mitsuba_vec3_drpt(wi),
                       dr.zeros(Array2f, n))


def to_mitsuba_vec3_drpt(v):
    return Array3f(*(Float(np.ascontiguousarray(v[i], np.float32)) for i in range(3)))


def sphere_dirs(n, seed):
    v = np.random.default_rng(seed).normal(size=(3, n))
    return (v / np.linalg.norm(v, axis=0)).astype(np.float32)


# ------------------------------------------------------------------ flattening
def test_mask_and_blend_weights_multiply():
    spec = complete(BSDFSpec("mask", {"opacity": 0.4},
                             [BSDFSpec("blendbsdf", {"weight": 0.25}, [two(diffuse()), diffuse()])]))
    comps = flatten(spec)
    assert [c.leaf.kind for c in comps] == ["null", "diffuse", "diffuse"]
    assert [c.weight for c in comps] == pytest.approx([0.6, 0.4 * 0.75, 0.4 * 0.25])
    assert [c.two_sided for c in comps] == [False, True, False]


def test_zero_weights_drop_components():
    comps = flatten(complete(BSDFSpec("mask", {"opacity": 1.0}, [two(diffuse())])))
    assert [c.leaf.kind for c in comps] == ["diffuse"]


def test_two_textured_weights_are_refused(tmp_path):
    t = Texture(tmp_path / "w.png", 0.5)
    spec = complete(BSDFSpec("mask", {"opacity": t},
                             [BSDFSpec("blendbsdf", {"weight": t}, [two(diffuse()), two(diffuse())])]))
    with pytest.raises(SceneError, match="textured weight"):
        MaterialTable(scene_with(spec))


def test_errors_and_notes_name_the_material_s_place(tmp_path):
    t = Texture(tmp_path / "w.png", 0.5)
    spec = complete(BSDFSpec("mask", {"opacity": t},
                             [BSDFSpec("blendbsdf", {"weight": t}, [two(diffuse()), two(diffuse())])]))
    s = scene_with(spec)
    s.materials[0].loc = Loc("lib.mtl", 7)
    with pytest.raises(SceneError) as e:
        MaterialTable(s)
    assert e.value.loc == Loc("lib.mtl", 7) and "material 'm0'" in e.value.message
    s.materials[0].loc = None  # a material built in code: at the scene file
    with pytest.raises(SceneError) as e:
        MaterialTable(s)
    assert e.value.loc == Loc("t.txt")
    bright = scene_with(diffuse())
    bright.materials[0] = Material("hot", kd=(0.8, 0.8, 0.8), ks=(0.5, 0.5, 0.5), loc=Loc("lib.mtl", 3))
    (note,) = MaterialTable(bright, "phong").notes  # Kd + Ks > 1
    assert note.startswith("lib.mtl:3: material 'hot': Kd + Ks"), note


# ------------------------------------------------------------------ sidedness
def test_one_sided_is_black_from_behind_and_twosided_is_not():
    table = MaterialTable(scene_with(diffuse(), two(diffuse())))
    n = 64
    wi = sphere_dirs(n, 1)
    wi[2] = -np.abs(wi[2])  # the viewer behind the surface
    wo = wi.copy()
    wo[0] = -wo[0]
    for m, expect_black in ((0, True), (1, False)):
        f, pdf = table.eval_pdf(interaction(wi, m), to_mitsuba_vec3_drpt(wo))
        f = np.array(f)
        assert (np.all(f == 0) and np.all(np.array(pdf) == 0)) == expect_black


# ------------------------------------------------------------------ against Mitsuba
CASES = {
    "blend": lambda: BSDFSpec("blendbsdf", {"weight": 0.3},
                              [diffuse((0.8, 0.2, 0.1)),
                               BSDFSpec("cook_torrance", {"kd": (0.9, 0.7, 0.3), "alpha": 0.1,
                                                          "metalness": 1.0})]),
    "mask": lambda: BSDFSpec("mask", {"opacity": 0.35}, [diffuse((0.3, 0.6, 0.9))]),
}


@pytest.mark.mitsuba
@pytest.mark.parametrize("name", sorted(CASES))
def test_eval_pdf_equal_mitsuba(name):
    mi = mitsuba()
    spec = complete(CASES[name]())
    table = MaterialTable(scene_with(spec))
    ref = mi.load_dict(to_mitsuba(spec))
    n = 4000
    wi, wo = sphere_dirs(n, 2), sphere_dirs(n, 3)
    wi[2] = np.abs(wi[2]) + 1e-3  # one-sided components: both sides are checked above
    wi /= np.linalg.norm(wi, axis=0)
    f, pdf = table.eval_pdf(interaction(wi, 0), to_mitsuba_vec3_drpt(wo))
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = to_mitsuba_vec3(wi)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    fm, pm = ref.eval_pdf(mi.BSDFContext(), si, to_mitsuba_vec3(wo))
    np.testing.assert_allclose(np.array(f), np.array(fm), rtol=2e-5, atol=1e-6)
    np.testing.assert_allclose(np.array(pdf), np.array(pm), rtol=2e-5, atol=1e-6)


@pytest.mark.mitsuba
def test_mask_passes_through_with_one_minus_opacity():
    table = MaterialTable(scene_with(complete(CASES["mask"]())))
    n = 20000
    wi = np.tile(np.array([[0.3], [0.2], [0.933]], np.float32), (1, n))
    wi /= np.linalg.norm(wi, axis=0)
    u = np.random.default_rng(4).random((3, n)).astype(np.float32)
    wo, bs = table.sample(interaction(wi, 0), Float(u[0]), Array2f(u[1], u[2]))
    wo, delta = np.array(wo), np.array(bs.delta)
    through = np.all(np.abs(wo + wi) < 1e-6, axis=0)
    assert np.array_equal(through, delta)
    assert abs(through.mean() - 0.65) < 4 * np.sqrt(0.65 * 0.35 / n)
    # a smooth sample weighs the mixture: f_mix / pdf_mix = kd for a masked Lambertian
    w = np.array(bs.weight)[:, ~delta]
    np.testing.assert_allclose(w, np.array([[0.3], [0.6], [0.9]]) * np.ones_like(w), rtol=1e-5)


def _rough(alpha=0.2):
    return BSDFSpec("roughconductor", {"alpha": alpha, "specular_reflectance": (0.7, 0.6, 0.5)})


@pytest.mark.parametrize("specs", [
    # every material one smooth lobe beside Dirac ones: the shortcut alone
    ("mask_rough", (BSDFSpec("mask", {"opacity": 0.35}, [_rough()]), diffuse())),
    # every multi-component material blends two smooth lobes: the evaluation alone
    ("blend", (CASES["blend"](),)),
    # both kinds of material in one table: chosen per lane
    ("both", (BSDFSpec("mask", {"opacity": 0.35}, [_rough()]), CASES["blend"](), diffuse())),
], ids=lambda s: s[0])
def test_sampled_weight_and_pdf_are_the_mixture_s(specs):
    """A smooth sample's ``weight`` is ``f_mix / pdf_mix`` and its ``pdf`` is ``pdf_mix``
    (:meth:`MaterialTable.eval_pdf` at the sampled direction), whether the table evaluates
    the mixture again (two smooth lobes) or takes the component's own (one smooth lobe
    beside a mask's pass-through). Negative control: without the slot's weight in the
    density, the masked lobe's pdf is off by ``1 / 0.35``."""
    _, specs = specs
    table = MaterialTable(scene_with(*(complete(s) for s in specs)))
    n = 4000
    for m in range(len(specs)):
        wi = sphere_dirs(n, 10 + m)
        wi[2] = np.abs(wi[2]) + 1e-3
        wi /= np.linalg.norm(wi, axis=0)
        u = np.random.default_rng(20 + m).random((3, n)).astype(np.float32)
        si = interaction(wi, m)
        wo, bs = table.sample(si, Float(u[0]), Array2f(u[1], u[2]))
        f, pdf = table.eval_pdf(si, wo)
        smooth = np.array(bs.valid) & ~np.array(bs.delta)
        assert smooth.sum() > n // 4
        p_s, p_e = np.array(bs.pdf)[smooth], np.array(pdf)[smooth]
        np.testing.assert_allclose(p_s, p_e, rtol=1e-4)
        w_e = np.array(f)[:, smooth] / p_e
        np.testing.assert_allclose(np.array(bs.weight)[:, smooth], w_e, rtol=1e-4, atol=1e-6)
        if specs[m].kind == "mask":  # negative control: the component's own density is not the mixture's
            assert not np.allclose(p_s / 0.35, p_e, rtol=1e-2)


# ------------------------------------------------------------------ reverse densities
REV_SPECS = (
    diffuse((0.8, 0.2, 0.1)),  # one-sided
    two(BSDFSpec("phong", {"kd": (0.4, 0.4, 0.4), "ks": (0.5, 0.5, 0.5), "ns": 20.0})),
    two(BSDFSpec("plastic", {"diffuse_reflectance": (0.5, 0.3, 0.2)})),  # a Dirac coating beside a smooth lobe
    two(_rough()),
    CASES["blend"](),  # two smooth lobes: the mixture evaluated again
    BSDFSpec("mask", {"opacity": 0.35}, [two(diffuse())]),  # one smooth lobe beside a pass-through
)


def _swapped(table, si, wo):
    """The reverse density the long way: ``eval_pdf`` of ``si`` seen from ``wo``, toward ``si.wi``."""
    rev_si = Interaction(si.valid, si.t, si.p, si.ng, si.ns, si.prim, si.material, wo, si.uv)
    return np.array(table.eval_pdf(rev_si, si.wi)[1])


def test_eval_pdf_rev_is_eval_pdf_both_ways():
    """:meth:`MaterialTable.eval_pdf_rev`'s ``f`` and ``pdf`` are :meth:`eval_pdf`'s, and its
    reverse density is ``eval_pdf`` with the directions swapped, bit for bit where ``wi`` and
    ``wo`` lie on one side of the surface (the same frame) and to rounding elsewhere (where a
    two-sided frame would flip: zero for these reflecting lobes), over a table of several
    kinds (branched dispatch), one- and two-sided, mixtures included. Negative control: the
    forward density in its place differs (none of these lobes is symmetric in its density)."""
    specs = [complete(s) for s in REV_SPECS]
    table = MaterialTable(scene_with(*specs))
    n = 4000
    for m in range(len(specs)):
        wi, wo = sphere_dirs(n, 30 + m), sphere_dirs(n, 40 + m)
        si = interaction(wi, m)
        wo_d = to_mitsuba_vec3_drpt(wo)
        f, pdf, rev = (np.array(v) for v in table.eval_pdf_rev(si, wo_d))
        f_e, pdf_e = (np.array(v) for v in table.eval_pdf(si, wo_d))
        rev_e = _swapped(table, si, wo_d)
        assert np.array_equal(f, f_e) and np.array_equal(pdf, pdf_e)
        same = (wi[2] < 0) == (wo[2] < 0)
        assert np.array_equal(rev[same], rev_e[same])
        np.testing.assert_allclose(rev[~same], rev_e[~same], rtol=1e-5, atol=1e-7)
        assert (rev[same] > 0).sum() > n // 8  # not a test of zeros
        # negative control: the forward density is not the reverse one
        assert not np.allclose(pdf[same], rev_e[same], rtol=1e-3)


def test_prepare_rev_evaluates_as_eval_pdf_rev():
    """:meth:`MaterialTable.prepare_rev`: one vertex prepared once, then evaluated toward
    several directions, gives :meth:`eval_pdf_rev`'s values bit for bit, over lanes of every
    material of a table of several kinds (branched dispatch; one- and two-sided, mixtures,
    a Dirac coating and a pass-through beside smooth lobes). Negative control: a vertex
    prepared with another ``wi`` differs (what is prepared is the vertex, not the direction)."""
    specs = [complete(s) for s in REV_SPECS]
    table = MaterialTable(scene_with(*specs))
    n = 4000
    wi = sphere_dirs(n, 70)
    si = interaction(wi, 0)
    si.material = UInt32(np.random.default_rng(71).integers(0, len(specs), n).astype(np.uint32))
    evaluate = table.prepare_rev(si)
    other = table.prepare_rev(interaction(sphere_dirs(n, 72), 0))
    for seed in (73, 74, 75):
        wo = to_mitsuba_vec3_drpt(sphere_dirs(n, seed))
        got = [np.array(v) for v in evaluate(wo)]
        want = [np.array(v) for v in table.eval_pdf_rev(si, wo)]
        for g, w in zip(got, want):
            assert np.array_equal(g, w)
        assert (want[2] > 0).sum() > n // 8  # not a test of zeros
        assert not np.array_equal(np.array(other(wo)[2]), want[2])


def test_sample_rev_is_the_swapped_density_of_the_sample():
    """:meth:`MaterialTable.sample` with ``rev``: the same sample as without it, and the reverse
    density of a smooth sample is ``eval_pdf`` seen from the sampled direction toward ``wi``
    (bit for bit: the sampled lobe evaluates it in its own frame, or the mixture evaluates it
    again), 0 after a Dirac lobe (plastic's coating, a mask's pass-through). Negative control:
    the sample's own (forward) density in its place differs. The material ids are opaque, as a
    render's are: with literal ids Dr.Jit folds the material's parameters (small tables are
    literals, :mod:`drpt.render.tables`) into each path's arithmetic at trace time, where its
    exact reciprocals and square roots are not the kernel's, and the two paths then differ in
    the last bits (the rough conductor: 489 of 3936 lanes, 1.9e-6 at most)."""
    specs = [complete(s) for s in REV_SPECS]
    table = MaterialTable(scene_with(*specs))
    n = 4000
    for m in range(len(specs)):
        wi = sphere_dirs(n, 50 + m)
        u = np.random.default_rng(60 + m).random((3, n)).astype(np.float32)
        si = interaction(wi, m)
        si.material = dr.opaque(UInt32, m, n)  # a render's ids: not literals (see the docstring)
        wo, bs = table.sample(si, Float(u[0]), Array2f(u[1], u[2]))
        wo_r, bs_r, rev = table.sample(si, Float(u[0]), Array2f(u[1], u[2]), rev=True)
        dr.eval(wo, bs, wo_r, bs_r, rev)
        assert np.array_equal(np.array(wo), np.array(wo_r))
        for field in ("weight", "pdf", "valid", "delta"):
            assert np.array_equal(np.array(getattr(bs, field)), np.array(getattr(bs_r, field)))
        smooth = np.array(bs.valid) & ~np.array(bs.delta)
        assert smooth.sum() > n // 8
        rev, rev_e = np.array(rev), _swapped(table, si, wo_r)
        assert np.array_equal(rev[smooth], rev_e[smooth])
        assert np.all(rev[np.array(bs.delta)] == 0.0)
        assert not np.allclose(np.array(bs.pdf)[smooth], rev_e[smooth], rtol=1e-3)  # negative control
# ------------------------------------------------------------------ one dispatch for eval and sample
def _fused_scene():
    from drpt.materials.spec import Checkerboard

    board = Checkerboard(color0=(0.9, 0.9, 0.9), color1=(0.2, 0.2, 0.2), to_uv=(4, 0, 0, 0, 4, 0, 0, 0, 1))
    return scene_with(*(complete(s) for s in (
        BSDFSpec("mask", {"opacity": board}, [two(diffuse((0.3, 0.6, 0.9)))]),  # textured slot weights
        CASES["blend"](),  # two smooth components
        _rough(0.3),
        BSDFSpec("conductor", {"specular_reflectance": (0.9, 0.8, 0.6)}),  # Dirac only
        two(BSDFSpec("roughplastic", {"alpha": 0.15, "diffuse_reflectance": (0.3, 0.17, 0.08)})),
        diffuse())))


def _fused_lanes(n: int, materials: int, seed: int):
    rng = np.random.default_rng(seed)
    wi, wo = sphere_dirs(n, seed), sphere_dirs(n, seed + 1)
    u = rng.random((5, n)).astype(np.float32)
    z = Array3f(dr.full(Float, 0.0, n), dr.full(Float, 0.0, n), dr.full(Float, 1.0, n))
    si = Interaction(dr.full(Bool, True, n), dr.full(Float, 1.0, n), dr.zeros(Array3f, n), z, z,
                     dr.zeros(UInt32, n), UInt32(rng.integers(0, materials, n).astype(np.uint32)),
                     to_mitsuba_vec3_drpt(wi), Array2f(u[3], u[4]))
    return si, to_mitsuba_vec3_drpt(wo), Float(u[0]), Array2f(u[1], u[2])


@pytest.mark.parametrize("dispatch", ["kinds", "masked"])
def test_eval_pdf_sample_is_eval_pdf_and_sample(dispatch, monkeypatch):
    """:meth:`MaterialTable.eval_pdf_sample` (the path tracer's one dispatch per vertex)
    returns exactly :meth:`~MaterialTable.eval_pdf` and :meth:`~MaterialTable.sample`,
    bit for bit, on a table of six kinds, a textured mask and a blend of two smooth lobes
    (slots sampled by the lanes that picked them), each dispatch; its
    :meth:`~MaterialTable.specular` view samples the delta-only material's lanes as the
    table does. Negative controls: the view's samples differ on the other lanes; the
    fused dispatch with every slot's cases sampling all their lanes (not only those that
    picked the slot) differs from ``sample`` on the mask's lanes."""
    monkeypatch.setattr(MaterialTable, "dispatch", dispatch)
    scene = _fused_scene()
    table = MaterialTable(scene)
    assert table.K == 2 and len(table.kinds) == 6
    si, wo, u1, u2 = _fused_lanes(4000, len(scene.materials), 3)

    sep = (*table.eval_pdf(si, wo), *table.sample(si, u1, u2))
    fused = table.eval_pdf_sample(si, wo, u1, u2)
    pairs = [(sep[0], fused[0]), (sep[1], fused[1]), (sep[2], fused[2])]
    pairs += [(getattr(sep[3], k), getattr(fused[3], k)) for k in ("wo", "weight", "pdf", "valid", "delta", "eta")]
    for a, b in pairs:
        assert np.array_equal(np.array(a), np.array(b))
    bs = sep[3]
    assert np.array(bs.valid).mean() > 0.3 and np.array(bs.delta).any() and np.array(sep[1]).max() > 0.0
    # the specular view (the delta-only materials' lanes: the conductor's) samples as the table
    # does there; elsewhere it does not (it traces only the conductor)
    conductor = np.array(si.material) == 3
    spec_wo = np.array(table.specular().sample(si, u1, u2)[1].wo)
    assert np.array_equal(spec_wo[:, conductor], np.array(bs.wo)[:, conductor])
    assert not np.array_equal(spec_wo[:, ~conductor], np.array(bs.wo)[:, ~conductor])

    # negative control: the sample drawn by every case of every slot, the last slot winning
    pick = MaterialTable._pick

    def every_slot(self, slots, u1_):
        picked, w, u = pick(self, slots, u1_)
        return [dr.full(Bool, True, dr.width(u1_)) for _ in picked], w, u

    monkeypatch.setattr(MaterialTable, "_pick", every_slot)
    bad = table.eval_pdf_sample(si, wo, u1, u2)[3]
    mask_lanes = np.array(si.material) == 0
    assert not np.array_equal(np.array(bad.wo)[:, mask_lanes], np.array(bs.wo)[:, mask_lanes])


def test_slots_are_read_on_the_lanes_of_several_components_only():
    """``MaterialTable._slots_at`` reads the slots in a symbolic ``if`` on the lanes whose
    material has several components (the mask, the blend) and gives the one-component
    materials' lanes slot 0's row at weight 1: every slot's rows, weights and presence are
    :meth:`_slot`'s bit for bit. Negative control: with every material taken for one
    component, the mask's and the blend's lanes differ."""
    scene = _fused_scene()
    table = MaterialTable(scene)
    assert table._multi is not None  # some materials are one component: the branch is traced
    si = _fused_lanes(2000, len(scene.materials), 5)[0]

    def values(slots):
        return [np.array(v) for s in slots for v in s]

    direct = values([table._slot(si, j) for j in range(table.K)])
    for a, b in zip(values(table._slots_at(si)), direct):
        assert np.array_equal(a, b)
    table._multi = Bool(np.zeros(len(scene.materials), bool))
    assert any(not np.array_equal(a, b) for a, b in zip(values(table._slots_at(si)), direct))
