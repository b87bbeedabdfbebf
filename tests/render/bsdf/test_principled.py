"""The full ``principled`` lobe (drpt/render/bsdf/principled.py) against
Mitsuba 3's ``principled`` plugin:

* eval AND pdf equal Mitsuba's on thousands of random (wi, wo) pairs per
  parameter set -- both sides, grazing, near the mirror and the refracted
  directions -- for sets that switch every lobe on (metallic, spec_tint,
  anisotropic, sheen(+tint), clearcoat, flatness, spec_trans from both sides,
  eta < 1, sampling rates, and one checkerboard cell of each of the corpus's
  test_texturedprincipled1/2 scenes); relative 1e-4 (measured ~1e-6), the pdf's
  two documented departures handled explicitly;
* each perturbed parameter is caught by that comparison (negative control);
* chi-square of sample against pdf at 0/45/80/89 degrees, from the front
  and (transmissive sets) from inside, the sharp corpus cells on finer grids;
  a wrong pdf is rejected (on those grids too);
* albedo equals Mitsuba's (its own, independent sampler); furnace bounds
  where principled conserves energy (metal, glass) and pinned excess where it
  does not (Burley diffuse, sheen, clearcoat);
* weight == eval/pdf, BSDFSample.eta, finiteness at the extremes (roughness
  0..1, eta 0.5..4 and 1.0, cos 1e-6), derive()'s rules and errors, the
  trace-time lobe selection and the table gather.
"""

from __future__ import annotations

import math
from pathlib import Path

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array2f, Array3f, Float, UInt32

from drpt.export.mitsuba_bsdf import to_mitsuba
from drpt.materials.bsdf_kinds import defaults, transmits
from drpt.materials.spec import BSDFSpec, Texture, complete
from drpt.render.bsdf import REGISTRY, lobe
from drpt.render.bsdf import principled as pr
from drpt.render.material import MaterialTable
from drpt.render.surface import Interaction
from drpt.scene.model import Background, Material, PerspectiveCamera, Planes, Scene, Spheres, Triangles
from drpt.testing import mitsuba, spherical_chi2, to_drpt, to_mitsuba_float, to_mitsuba_vec3

RED = (0.8, 0.2, 0.4)
WHITE = (1.0, 1.0, 1.0)

#: parameter sets (Mitsuba's names); together they switch every lobe and branch on
CASES = {
    "default": {},
    "metal": {"base_color": (0.9, 0.6, 0.3), "metallic": 1.0, "roughness": 0.3},
    "spec_tint": {"base_color": RED, "metallic": 0.4, "spec_tint": 0.7, "roughness": 0.4},
    "anisotropic": {"base_color": RED, "metallic": 0.5, "anisotropic": 0.8, "roughness": 0.5},
    "sheen": {"base_color": RED, "sheen": 1.0, "sheen_tint": 0.6, "roughness": 0.7},
    "clearcoat": {"clearcoat": 1.0, "clearcoat_gloss": 0.8, "roughness": 0.6},
    "flatness": {"base_color": RED, "flatness": 0.7, "roughness": 0.8},
    "specular": {"specular": 0.9, "roughness": 0.2},
    "glass": {"base_color": (0.9, 0.8, 0.5), "spec_trans": 1.0, "roughness": 0.2},
    # brdf = 0: the sheen is still added (Mitsuba's JIT variants evaluate it
    # whenever its own mask holds; a scalar variant would skip it here)
    "glass_sheen": {"spec_trans": 1.0, "sheen": 0.8, "sheen_tint": 0.5, "base_color": RED, "roughness": 0.5},
    "all": {"base_color": RED, "roughness": 0.45, "metallic": 0.2, "spec_tint": 0.4, "anisotropic": 0.5,
            "sheen": 0.6, "sheen_tint": 0.3, "clearcoat": 0.7, "clearcoat_gloss": 0.4, "spec_trans": 0.6,
            "flatness": 0.3, "eta": 1.33, "diffuse_reflectance_sampling_rate": 0.5,
            "main_specular_sampling_rate": 2.0, "clearcoat_sampling_rate": 0.7},
    "less_dense": {"spec_trans": 0.5, "eta": 0.5, "roughness": 0.8, "clearcoat": 1.0, "metallic": 0.2},
    "smooth": {"metallic": 0.3, "spec_trans": 0.4, "roughness": 0.0, "eta": 1.6},
    # a checkerboard cell of the corpus's test_texturedprincipled1_path and ...2_path each
    "corpus1": {"base_color": (0.2, 0.8, 0.1), "roughness": 0.15, "anisotropic": 0.8, "metallic": 0.1,
                "clearcoat": 0.9, "sheen": 0.9, "specular": 0.7},
    "corpus2": {"base_color": (0.3, 0.6, 0.8), "roughness": 0.15, "anisotropic": 0.7, "spec_trans": 0.7,
                "clearcoat": 0.6, "sheen": 0.9, "specular": 0.4},
}


def _mi_bsdf(mi, prm):
    d = {"type": "principled"}
    for k, v in prm.items():
        d[k] = {"type": "rgb", "value": list(v)} if k == "base_color" else v
    return mi.load_dict(d)


def _sphere(n, seed):
    v = np.random.default_rng(seed).normal(size=(3, n))
    return v / np.linalg.norm(v, axis=0)


def _dir_np(theta_deg, side=1.0):
    t = np.radians(theta_deg)
    return np.array([np.sin(t), 0.0, side * np.cos(t)])


def _dir(theta_deg, n, side=1.0):
    return Array3f(*(Float(np.full(n, x, np.float32)) for x in _dir_np(theta_deg, side)))


def _uniform(n, dims, seed):
    return np.random.default_rng(seed).random((dims, n)).astype(np.float32)


def _bsdf_weight(prm):
    full = {**defaults("principled"), **prm}
    return (1.0 - full["metallic"]) * full["spec_trans"]


def _eta(prm):
    return pr.derive({**defaults("principled"), **prm})["eta_ratio"]


def _pairs(prm, n, seed):
    """(wi, wo) float32 (3, n): wi on the whole sphere (10 % grazing, |cos| down
    to 1e-6); wo a quarter uniform, a quarter near wi's mirror direction, a
    quarter near its refraction through the macro-surface, the rest grazing."""
    rng = np.random.default_rng(seed)
    wi = _sphere(n, seed)
    g = rng.random(n) < 0.1
    z = np.sign(wi[2, g]) * 10.0 ** rng.uniform(-6, -2, g.sum())
    wi[:2, g] *= np.sqrt(1 - z**2) / np.linalg.norm(wi[:2, g], axis=0)
    wi[2, g] = z
    spread = 0.3 * max(defaults("principled")["roughness"] if "roughness" not in prm else prm["roughness"],
                       0.03) ** 2 + 2e-3
    wo = _sphere(n, seed + 1)
    q = n // 4
    mirror = np.array([-wi[0], -wi[1], wi[2]]) + spread * _sphere(n, seed + 2)
    wo[:, q:2 * q] = mirror[:, q:2 * q]
    eta = _eta(prm)
    eta_p = np.where(wi[2] > 0, eta, 1.0 / eta)  # n_far / n_near
    sin2 = (1 - wi[2] ** 2) / eta_p**2
    tir = sin2 >= 1
    refr = np.array([-wi[0] / eta_p, -wi[1] / eta_p, -np.sign(wi[2]) * np.sqrt(np.maximum(1 - sin2, 0))])
    refr = np.where(tir, mirror, refr) + spread * _sphere(n, seed + 3)
    wo[:, 2 * q:3 * q] = refr[:, 2 * q:3 * q]
    wo /= np.linalg.norm(wo, axis=0)
    k = slice(3 * q, n)
    zo = rng.choice([-1.0, 1.0], n - 3 * q) * 10.0 ** rng.uniform(-6, -2, n - 3 * q)
    wo[:2, k] *= np.sqrt(1 - zo**2) / np.linalg.norm(wo[:2, k], axis=0)
    wo[2, k] = zo
    return wi.astype(np.float32), wo.astype(np.float32)


def _ours(p, wi, wo):
    a, b = to_drpt(wi, Array3f), to_drpt(wo, Array3f)
    return np.array(pr.eval(p, a, b)), np.array(pr.pdf(p, a, b))


def _theirs(mi, prm, wi, wo):
    bsdf = _mi_bsdf(mi, prm)
    si = dr.zeros(mi.SurfaceInteraction3f, wi.shape[1])
    si.wi = to_mitsuba_vec3(wi)  # local = world: principled reads si.wi only
    ctx = mi.BSDFContext()
    return (np.array(bsdf.eval(ctx, si, to_mitsuba_vec3(wo))),
            np.array(bsdf.pdf(ctx, si, to_mitsuba_vec3(wo))))


def _ratio_error(wi, wo):
    """``|dot(wi, h) / dot(wo, h) - 1|`` in float32 for reflections (0 for the rest):
    Mitsuba's main-reflection pdf carries this ratio, drpt's cancels it."""
    reflect = wi[2] * wo[2] > 0
    h = (wi + wo) / np.maximum(np.linalg.norm(wi + wo, axis=0), 1e-30)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.abs(np.sum(wi * h, axis=0) / np.sum(wo * h, axis=0) - 1.0)
    return np.where(reflect & np.isfinite(ratio), ratio, 0.0)


def _compare(prm, mi_prm=None, n=8000, seed=1):
    """Relative errors of drpt's eval/pdf (parameters ``prm``) against
    Mitsuba's (``mi_prm``, default the same): (eval, pdf on clean lanes, pdf
    elsewhere in units of its allowance) and the data."""
    mi = mitsuba()
    wi, wo = _pairs(prm, n, seed)
    f_d, p_d = _ours(pr.from_params(prm), wi, wo)
    f_m, p_m = _theirs(mi, prm if mi_prm is None else mi_prm, wi, wo)
    assert np.all(np.isfinite(f_d)) and np.all(f_d >= 0) and np.all(np.isfinite(p_d)) and np.all(p_d >= 0)
    # Departure 1: from inside a non-transmitting lane (bsdf = 0) Mitsuba's eval
    # is 0 and its sample rejects, but its pdf is a reflection's; drpt's is 0.
    back0 = (wi[2] < 0) & (_bsdf_weight(prm) == 0.0)
    assert np.all(f_d[:, back0] == 0) and np.all(p_d[back0] == 0)
    if mi_prm is None:
        assert np.all(f_m[:, back0] == 0)
    p_m = np.where(back0, 0.0, p_m)
    # Departure 2: the main reflection's pdf has dot(wi, h) / dot(wo, h) = 1
    # cancelled in drpt; Mitsuba's float32 ratio is off near wo ~ -wi.
    ratio = _ratio_error(wi, wo)
    clean = ratio < 1e-5
    ef = np.abs(f_d - f_m) / (np.abs(f_m) + 1e-7 * f_m.max())
    ep = np.abs(p_d - p_m) / (np.abs(p_m) + 1e-7 * p_m.max())
    e_rest = np.abs(p_d - p_m) / ((2 * ratio + 1e-4) * p_m + 1e-7 * p_m.max())
    return ef.max(), ep[clean].max(), e_rest.max(), dict(wi=wi, wo=wo, f=f_d, f_m=f_m, clean=clean)


# ---------------------------------------------------- equality with Mitsuba
@pytest.mark.mitsuba
@pytest.mark.parametrize("name", list(CASES))
def test_eval_and_pdf_equal_mitsuba(name):
    prm = CASES[name]
    e_f, e_p, e_rest, d = _compare(prm)
    assert e_f < 1e-4, e_f
    assert e_p < 1e-4, e_p
    assert e_rest <= 1.0, e_rest
    assert d["clean"].mean() > 0.9
    # the comparison covers the lobes: nonzero values in reflection, and in
    # transmission from both sides where the material transmits
    f, wi, wo = d["f_m"], d["wi"], d["wo"]
    refl = (wi[2] * wo[2] > 0) & (f.max(axis=0) > 0)
    assert refl.mean() > 0.15
    if _bsdf_weight(prm) > 0:
        for side in (1, -1):
            trans = (wi[2] * side > 0) & (wi[2] * wo[2] < 0) & (f.max(axis=0) > 0)
            assert trans.mean() > 0.02, (side, trans.mean())
            back_refl = (wi[2] * side > 0) & refl
            assert back_refl.mean() > 0.02


# Each lobe's parameter, perturbed on Mitsuba's side only, must be caught.
NEGATIVE = [("all", "roughness", 0.47), ("all", "metallic", 0.22), ("all", "spec_tint", 0.45),
            ("all", "anisotropic", 0.55), ("all", "sheen", 0.65), ("all", "sheen_tint", 0.35),
            ("all", "clearcoat", 0.75), ("all", "clearcoat_gloss", 0.45), ("all", "spec_trans", 0.62),
            ("all", "flatness", 0.33), ("all", "eta", 1.35), ("all", "base_color", (0.8, 0.21, 0.4)),
            ("all", "main_specular_sampling_rate", 2.2), ("all", "clearcoat_sampling_rate", 0.8),
            ("all", "diffuse_reflectance_sampling_rate", 0.55), ("specular", "specular", 0.85)]


@pytest.mark.mitsuba
@pytest.mark.parametrize("name,key,value", NEGATIVE)
def test_negative_control_perturbed_parameter_is_caught(name, key, value):
    prm = CASES[name]
    e_f, e_p, e_rest, _ = _compare(prm, {**prm, key: value}, n=4000)
    if "sampling_rate" in key:  # rates change the pdf only
        assert e_f < 1e-4 and (e_p > 1e-3 or e_rest > 10), (e_f, e_p, e_rest)
    else:
        assert e_f > 1e-3, e_f


@pytest.mark.mitsuba
def test_defaults_and_parameter_names_are_mitsubas():
    # Every drpt parameter name is one Mitsuba's principled reads (it raises on
    # an unused one), and drpt's defaults are Mitsuba's: the plugin given all
    # of them explicitly equals the plugin given none.
    mi = mitsuba()
    explicit = {k: v for k, v in defaults("principled").items() if v is not None}
    wi, wo = _pairs({}, 4000, 7)
    a = _theirs(mi, explicit, wi, wo)
    b = _theirs(mi, {}, wi, wo)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert (a[0] > 0).mean() > 0.2
    with pytest.raises(RuntimeError, match="unreferenced"):
        _mi_bsdf(mi, {"not_a_parameter": 1.0})
    assert REGISTRY["principled"] == "principled" and lobe("principled") is pr


# -------------------------------------------- trace-time lobe selection
def test_lobes_of_follows_mitsubas_flags():
    assert pr.lobes_of([{}]) == pr.NONE
    assert pr.lobes_of([{"clearcoat": 0.0}, {"sheen": 0.5}]) == pr.Lobes(
        **{**{f: False for f in pr.NONE.__dataclass_fields__}, "sheen": True})
    tex = object()  # a texture counts even if its values were 0 (Mitsuba's get_flag)
    assert pr.lobes_of([{"spec_trans": tex}]).spec_trans
    assert not pr.lobes_of([{"spec_trans": np.float32(0.0), "sheen": 0}]).spec_trans
    assert pr.lobes_of([{"sheen": np.float32(0.5)}]).sheen
    assert pr.lobes_of([CASES["all"]]) == pr.ALL


@pytest.mark.parametrize("name", ["default", "sheen", "glass"])
def test_specialized_trace_equals_full_trace(name):
    # Tracing only the lobes the material needs gives the values of tracing all
    # (test_eval_and_pdf_equal_mitsuba compares every case's specialized trace
    # with Mitsuba; this also covers sample).
    prm = CASES[name]
    wi, wo = _pairs(prm, 3000, 3)
    a = _ours(pr.from_params(prm, pr.ALL), wi, wo)
    b = _ours(pr.from_params(prm), wi, wo)
    for x, y in zip(a, b):
        assert np.allclose(x, y, rtol=1e-6, atol=1e-7 * max(x.max(), 1e-30))
    u = _uniform(3000, 3, 4)
    wi1 = _dir(50.0, 3000, -1.0 if _bsdf_weight(prm) > 0 else 1.0)
    sa = pr.sample(pr.from_params(prm, pr.ALL), wi1, Float(u[0]), Array2f(u[1], u[2]))
    sb = pr.sample(pr.from_params(prm), wi1, Float(u[0]), Array2f(u[1], u[2]))
    assert np.array_equal(np.array(sa.valid), np.array(sb.valid))
    assert np.allclose(np.array(sa.wo), np.array(sb.wo), atol=1e-6)
    assert np.allclose(np.array(sa.weight), np.array(sb.weight), rtol=1e-5, atol=1e-7)


class _FakeTable:
    """The material table's lookup interface over one-value-per-material arrays."""

    def __init__(self, specs, texture_values=None):
        self.specs = specs
        self.asked = []
        self.texture_values = texture_values or {}

    def specs_of(self, kind):
        assert kind == "principled"
        return self.specs

    def value(self, name, si, active):
        self.asked.append(name)
        vals = []
        for s in self.specs:
            prm = {**defaults("principled"), **s}
            prm.update(pr.derive(prm))
            vals.append(self.texture_values.get(name, prm[name]))
        idx = si
        if name == "base_color":
            a = np.array(vals, np.float32).T
            return dr.gather(Array3f, Array3f(*(Float(x) for x in a)), idx, active)
        return dr.gather(Float, Float(np.array(vals, np.float32)), idx, active)


def test_params_gathers_only_the_needed_fields():
    specs = [{"base_color": RED, "roughness": 0.3}, {"sheen": 0.5, "metallic": 1.0}]
    t = _FakeTable(specs)
    p = pr.params(t, UInt32([1, 0, 1]), dr.full(dr.auto.Bool, True, 3))
    assert p.lobes == pr.Lobes(**{**{f: False for f in pr.NONE.__dataclass_fields__},
                                  "sheen": True, "metallic": True})
    assert set(t.asked) == {"base_color", "roughness", "metallic", "sheen", "eta_ratio",
                            "diffuse_reflectance_sampling_rate", "main_specular_sampling_rate"}
    assert np.allclose(np.array(p.roughness), [0.5, 0.3, 0.5])
    assert np.allclose(np.array(p.metallic), [1, 0, 1]) and np.allclose(np.array(p.sheen), [0.5, 0, 0.5])
    assert np.allclose(np.array(p.base_color)[0], [0.5, 0.8, 0.5])
    assert np.allclose(np.array(p.eta), 1.5) and np.all(np.array(p.clearcoat) == 0)
    # every field FIELDS names is a parameter or derive()'s output
    assert set(pr.FIELDS) <= set(defaults("principled")) | {"eta_ratio"}
    # a texture's value outside [0, 1] is clipped (numbers are refused by derive)
    t = _FakeTable(specs, {"roughness": 1.7, "sheen": -0.2})
    p = pr.params(t, UInt32([0, 1]), dr.full(dr.auto.Bool, True, 2))
    assert np.all(np.array(p.roughness) == 1.0) and np.all(np.array(p.sheen) == 0.0)


# ------------------------------------------- through the material table
def _scene(specs):
    cam = PerspectiveCamera((0, 0, 5), (0, 0, -1), (0, 1, 0), 40.0)
    mats = [Material(f"m{i}", bsdf=s) for i, s in enumerate(specs)]
    pos = np.array([[[-1.0, -1, 0], [1, -1, 0], [1, 1, 0]]] * len(specs))
    return Scene(Path("t.txt"), cam, mats, Triangles(pos, np.arange(len(specs), dtype=np.int32),
                                                     uvs=np.zeros((len(specs), 3, 2))),
                 Spheres.empty(), Planes.empty(), [], Background())


def _interaction(wi, material):
    n = wi.shape[1]
    z = Array3f(dr.zeros(Float, n), dr.zeros(Float, n), dr.full(Float, 1.0, n))
    return Interaction(dr.full(dr.auto.Bool, True, n), dr.full(Float, 1.0, n), dr.zeros(Array3f, n), z, z,
                       dr.zeros(UInt32, n), UInt32(np.asarray(material, np.uint32)), to_drpt(wi, Array3f),
                       dr.zeros(Array2f, n))


@pytest.mark.mitsuba
def test_material_table_renders_principled_as_mitsuba():
    # Several principled materials (one-sided, twosided, transmissive, anisotropic)
    # and a diffuse one in one table: derive(), the uploaded FIELDS, params() and
    # the union of the lobes they need, against Mitsuba's plugins (exported).
    mi = mitsuba()
    leaves = [CASES["all"], CASES["clearcoat"], {**CASES["anisotropic"], "roughness": 0.3}, CASES["glass"]]
    specs = [complete(BSDFSpec("principled", dict(p))) for p in leaves]
    specs.append(complete(BSDFSpec("twosided", {}, [BSDFSpec("principled", dict(CASES["sheen"]))])))
    specs.append(complete(BSDFSpec("diffuse", {"kd": (0.3, 0.4, 0.5)})))
    table = MaterialTable(_scene(specs))
    assert table.lobes["principled"] is pr
    n = 3000
    for m, spec in enumerate(specs):
        wi, wo = _pairs(leaves[m] if m < len(leaves) else {}, n, 20 + m)
        f, pdf = table.eval_pdf(_interaction(wi, np.full(n, m)), to_drpt(wo, Array3f))
        ref = mi.load_dict(to_mitsuba(spec))
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        si.wi = to_mitsuba_vec3(wi)
        si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
        fm, pm = ref.eval_pdf(mi.BSDFContext(), si, to_mitsuba_vec3(wo))
        f, fm, pdf, pm = np.array(f), np.array(fm), np.array(pdf), np.array(pm)
        if spec.kind == "principled" and _bsdf_weight(spec.params) == 0:
            pm = np.where(wi[2] < 0, 0.0, pm)  # the documented departure
        np.testing.assert_allclose(f, fm, rtol=1e-4, atol=1e-6 * fm.max())
        allowed = (2 * _ratio_error(wi, wo) + 1e-4) * pm + 1e-7 * pm.max()
        assert np.all(np.abs(pdf - pm) <= allowed), m
        assert (f.max(axis=0) > 0).mean() > 0.2
    # sampling through the table: finite, weight = f / pdf of the mixture
    mat = np.arange(6 * 2000) // 2000
    wi = np.repeat(_dir_np(40.0)[:, None], mat.size, axis=1).astype(np.float32)
    wi[2, ::2] *= -1  # half from behind
    u = _uniform(mat.size, 3, 5)
    si = _interaction(wi, mat)
    wo, bs = table.sample(si, Float(u[0]), Array2f(u[1], u[2]))
    f, pdf = table.eval_pdf(si, wo)
    w, valid = np.array(bs.weight), np.array(bs.valid)
    assert np.all(np.isfinite(w)) and valid.mean() > 0.3
    ok = valid & (np.array(pdf) > 0)
    np.testing.assert_allclose(w[:, ok], np.array(f)[:, ok] / np.array(pdf)[ok], rtol=1e-4)


def test_twosided_refuses_transmitting_principled():
    # Mitsuba's twosided refuses a BSDF with a transmission component: principled
    # with spec_trans given non-zero (a texture counts), not with spec_trans = 0.
    assert transmits("principled", {"spec_trans": 0.5}) and transmits("dielectric", {})
    assert not transmits("principled", {"spec_trans": 0.0}) and not transmits("principled", {})
    assert transmits("principled", {"spec_trans": Texture(Path("t.png"), 0.0)})
    with pytest.raises(ValueError, match="transmissive BSDF 'principled'"):
        complete(BSDFSpec("twosided", {}, [BSDFSpec("principled", {"spec_trans": 0.5})]))
    complete(BSDFSpec("twosided", {}, [BSDFSpec("principled", {"spec_trans": 0.0})]))


@pytest.mark.mitsuba
def test_mitsubas_twosided_refuses_transmitting_principled_too():
    mi = mitsuba()
    with pytest.raises(RuntimeError, match="transmission"):
        mi.load_dict({"type": "twosided", "bsdf": {"type": "principled", "spec_trans": 0.5}})
    mi.load_dict({"type": "twosided", "bsdf": {"type": "principled", "spec_trans": 0.0}})


# --------------------------------------------------------------- derive
def test_derive_eta_rules():
    d = defaults("principled")
    assert pr.derive(d)["eta_ratio"] == pytest.approx(1.5, abs=1e-6)
    assert pr.derive({**d, "specular": 0.9})["eta_ratio"] == pytest.approx(
        2 / (1 - math.sqrt(0.072)) - 1, rel=1e-6)
    assert pr.derive({**d, "eta": 1.33, "specular": 0.1})["eta_ratio"] == pytest.approx(1.33)
    # Mitsuba's clamps, only for transmitting materials
    assert pr.derive({**d, "eta": 1.0})["eta_ratio"] == 1.0
    assert pr.derive({**d, "eta": 1.0, "spec_trans": 0.5})["eta_ratio"] == pytest.approx(1.001)
    assert pr.derive({**d, "specular": 0.0})["eta_ratio"] == 1.0
    e = pr.derive({**d, "specular": 0.0, "spec_trans": object()})["eta_ratio"]
    assert e == pytest.approx(2 / (1 - math.sqrt(0.08e-3)) - 1, rel=1e-6)


@pytest.mark.parametrize("bad", [{"roughness": 1.5}, {"metallic": -0.1}, {"clearcoat_gloss": 2.0},
                                 {"eta": -1.0}, {"eta": 0.0}, {"eta": "glass"}, {"eta": math.inf},
                                 {"specular": 13.0}, {"specular": -1.0},
                                 {"clearcoat_sampling_rate": -1.0}, {"main_specular_sampling_rate": math.nan},
                                 {"roughness": np.float32(1.5)}, {"eta": True}])
def test_derive_refuses_bad_parameters(bad):
    with pytest.raises(ValueError, match="principled"):
        pr.derive({**defaults("principled"), **bad})


@pytest.mark.mitsuba
def test_derived_eta_matches_mitsubas_clamps():
    # eta 1 and specular 0 with transmission: Mitsuba's 1.001 / 1e-3 clamps.
    for prm in ({"eta": 1.0, "spec_trans": 0.7, "roughness": 0.5},
                {"specular": 0.0, "spec_trans": 0.7, "roughness": 0.5}):
        e_f, e_p, e_rest, _ = _compare(prm, n=4000)
        assert e_f < 1e-4 and e_p < 1e-4 and e_rest <= 1.0, (prm, e_f, e_p, e_rest)


# ------------------------------------------------------------- chi-square
# ROT maps the normal to +y so the horizon is the grid lines phi = 0, pi and
# the lobes lie on the equator (as in test_cook_torrance).
ROT = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
ANGLES = (0.0, 45.0, 80.0, 89.0)
CHI2_CASES = {
    "default": {},
    "metal_aniso": {"metallic": 0.7, "anisotropic": 0.8, "roughness": 0.3, "base_color": RED},
    "sheen_clearcoat": {"sheen": 1.0, "clearcoat": 1.0, "clearcoat_gloss": 0.5, "roughness": 0.9},
    "rates": {"clearcoat": 0.5, "diffuse_reflectance_sampling_rate": 0.2,
              "main_specular_sampling_rate": 3.0, "clearcoat_sampling_rate": 2.0, "roughness": 0.4},
    "all": CASES["all"],
    "glass": {"spec_trans": 1.0, "roughness": 0.3},
    "less_dense": CASES["less_dense"],
    "corpus1": CASES["corpus1"],
    "corpus2": CASES["corpus2"],
}
INSIDE = ("all", "glass", "less_dense", "corpus2")


def _chi2(p, theta, side=1.0, p_pdf=None, res=121, ires=8, count=200_000):
    mi = mitsuba()

    p_pdf = p if p_pdf is None else p_pdf

    def sample_func(u):
        a = np.array(u, dtype=np.float32)
        bs = pr.sample(p, _dir(theta, a.shape[1], side), Float(a[0]), Array2f(a[1], a[2]))
        return (to_mitsuba_vec3(ROT @ np.array(bs.wo, dtype=np.float64)),
                mi.Float(np.array(bs.valid).astype(np.float32)))

    def pdf_func(w):
        v = to_drpt(ROT.T @ np.array(w, dtype=np.float64), Array3f)
        return to_mitsuba_float(np.array(pr.pdf(p_pdf, _dir(theta, dr.width(v), side), v)))

    return spherical_chi2(sample_func, pdf_func, sample_dim=3, sample_count=count, res=res, ires=ires)


@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("theta", ANGLES)
@pytest.mark.parametrize("name", list(CHI2_CASES))
def test_sampling_matches_pdf_front(name, theta):
    # The corpus's cells are sharp and anisotropic (alpha_y 0.012 for roughness 0.15,
    # anisotropic 0.8): the 121 grid's pdf integration does not resolve them (corpus2 at 45
    # degrees: chi^2 4120 for 3392 d.o.f.; 8452 for 8290 on the 241 grid, and 361 at
    # grazing angles).
    res, ires = ((361, 24) if theta >= 80.0 else (241, 16)) if name.startswith("corpus") else (121, 8)
    ok, msg = _chi2(pr.from_params(CHI2_CASES[name]), theta, res=res, ires=ires)
    assert ok, msg


@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("theta", ANGLES)
@pytest.mark.parametrize("name", INSIDE)
def test_sampling_matches_pdf_inside(name, theta):
    # From inside at grazing angles the lobes are thin (total internal
    # reflection hugs the horizon): the 121 grid's pdf integration misses them
    # -- Mitsuba's own principled sample/pdf pair is rejected there on that
    # grid too (less_dense at 80 degrees) -- and a finer grid resolves them.
    res, ires = (241, 16) if theta >= 80.0 else (121, 8)
    ok, msg = _chi2(pr.from_params(CHI2_CASES[name]), theta, side=-1.0, res=res, ires=ires)
    assert ok, msg


@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("name,wrong,side", [
    ("all", {"roughness": 0.5}, 1.0),
    ("rates", {"diffuse_reflectance_sampling_rate": 0.3}, 1.0),
    ("sheen_clearcoat", {"clearcoat_gloss": 0.7}, 1.0),
    ("all", {"eta": 1.4}, -1.0)])
def test_chi2_negative_control(name, wrong, side):
    # The sampler of one material against the pdf of a slightly different one
    # (the main roughness 0.45 -> 0.5, the diffuse lobe's probability 5.8 -> 8.5 %,
    # the clearcoat's width, the IOR of the transmission) is rejected.
    prm = CHI2_CASES[name]
    ok, _ = _chi2(pr.from_params(prm), 45.0, side, p_pdf=pr.from_params({**prm, **wrong}))
    assert not ok


@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("name,wrong", [("corpus1", {"anisotropic": 0.75}), ("corpus2", {"spec_trans": 0.6})])
def test_chi2_negative_control_corpus_grid(name, wrong):
    # The finer grid of the corpus cells still rejects a slightly different pdf (the
    # anisotropy 0.8 -> 0.75: alpha_y 0.0119 -> 0.0128; the transmitted share of the specular).
    prm = CHI2_CASES[name]
    ok, _ = _chi2(pr.from_params(prm), 45.0, p_pdf=pr.from_params({**prm, **wrong}), res=241, ires=16)
    assert not ok


# ------------------------------------------------------ weights and albedo
@pytest.mark.parametrize("side", [1.0, -1.0])
@pytest.mark.parametrize("name", ["all", "glass", "less_dense", "metal", "clearcoat"])
def test_weight_is_eval_over_pdf(name, side):
    k = 20_000
    thetas = (0.0, 45.0, 80.0, 89.0)
    n = k * len(thetas)
    prm = CASES[name]
    p = pr.from_params(prm)
    u = _uniform(n, 3, 11)
    wi = to_drpt(np.repeat(np.array([_dir_np(t, side) for t in thetas]).T, k, axis=1), Array3f)
    bs = pr.sample(p, wi, Float(u[0]), Array2f(u[1], u[2]))
    f = np.array(pr.eval(p, wi, bs.wo))
    pdf = np.array(pr.pdf(p, wi, bs.wo))
    w, bpdf, valid = np.array(bs.weight), np.array(bs.pdf), np.array(bs.valid)
    wo, eta = np.array(bs.wo), np.array(bs.eta)
    assert np.array_equal(bpdf, np.where(valid, pdf, 0))
    assert np.allclose(w[:, valid], f[:, valid] / pdf[valid], rtol=1e-6)
    assert np.all(w[:, ~valid] == 0) and not np.any(np.array(bs.delta))
    assert np.allclose(np.linalg.norm(wo[:, valid], axis=0), 1.0, atol=1e-5)
    through = valid & (wo[2] * side < 0)
    e = _eta(prm)
    assert np.allclose(eta[through], e if side > 0 else 1 / e, rtol=1e-6)
    assert np.all(eta[valid & ~through] == 1.0)
    for i, theta in enumerate(thetas):
        lanes = slice(i * k, (i + 1) * k)
        if side < 0 and _bsdf_weight(prm) == 0:
            assert not valid[lanes].any()  # black from behind
        else:
            assert valid[lanes].mean() > 0.3, (theta, valid[lanes].mean())
            if _bsdf_weight(prm) > 0 and theta < 80:
                assert through[lanes].mean() > 0.05


def _albedo(prm, theta, side=1.0, n=200_000, seed=7):
    u = _uniform(n, 3, seed)
    bs = pr.sample(pr.from_params(prm), _dir(theta, n, side), Float(u[0]), Array2f(u[1], u[2]))
    w = np.array(bs.weight, dtype=np.float64)
    flux = w * np.array(bs.eta, dtype=np.float64) ** 2  # the radiance scaling undone
    return w.mean(axis=1), w.std(axis=1) / np.sqrt(n), w.max(), flux.mean(axis=1)


def _albedo_mitsuba(mi, prm, theta, side=1.0, n=200_000, seed=8):
    u = _uniform(n, 3, seed)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = to_mitsuba_vec3(np.repeat(_dir_np(theta, side)[:, None], n, axis=1))
    _, w = _mi_bsdf(mi, prm).sample(mi.BSDFContext(), si, mi.Float(u[0]), mi.Point2f(u[1], u[2]))
    w = np.array(w, dtype=np.float64)
    return w.mean(axis=1), w.std(axis=1) / np.sqrt(n)


@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("side", [1.0, -1.0])
@pytest.mark.parametrize("name", ["default", "anisotropic", "sheen", "clearcoat", "all", "glass",
                                  "less_dense"])
def test_albedo_equals_mitsubas(name, side):
    # Same model, independent samplers and random numbers.
    mi = mitsuba()
    prm = CASES[name]
    for theta in (0.0, 60.0, 85.0):
        a, ea, _, _ = _albedo(prm, theta, side)
        b, eb = _albedo_mitsuba(mi, prm, theta, side)
        assert np.all(np.abs(a - b) <= 4.5 * np.hypot(ea, eb) + 1e-6), (theta, a, b, ea, eb)
        if side < 0 and _bsdf_weight(prm) == 0:
            assert np.all(a == 0) and np.all(b == 0)


@pytest.mark.parametrize("roughness,aniso", [(0.0, 0.0), (0.3, 0.8), (0.7, 0.0), (1.0, 1.0)])
def test_furnace_metal_at_most_one(roughness, aniso):
    # Pure metal: only the specular lobe, weight = F G1(wo) <= 1 per sample.
    prm = {"base_color": WHITE, "metallic": 1.0, "roughness": roughness, "anisotropic": aniso}
    for theta in (0.0, 45.0, 80.0, 89.9):
        mean, err, wmax, _ = _albedo(prm, theta, n=50_000)
        assert np.all(mean <= 1.0 + 1e-6) and wmax <= 1.0 + 1e-5, (theta, mean, wmax)


@pytest.mark.parametrize("eta", [1.33, 1.5, 2.4, 0.6])
@pytest.mark.parametrize("side", [1.0, -1.0])
def test_furnace_glass_conserves_flux(eta, side):
    # Pure transmission lobe, white: reflected + transmitted energy <= 1 once the
    # radiance scaling 1/eta_it^2 of the transmitted weight is undone (w eta_it^2);
    # the radiance weight itself exceeds 1 going into the less dense side.
    prm = {"base_color": WHITE, "spec_trans": 1.0, "roughness": 0.3, "eta": eta}
    for theta in (0.0, 45.0, 80.0, 89.0):
        mean, err, _, flux = _albedo(prm, theta, side, n=100_000)
        assert np.all(flux <= 1.0 + 4 * err.max() + 1e-6), (theta, flux)
        assert np.all(flux > 0.8), (theta, flux)  # little lost to masking at alpha 0.09


def test_principled_is_not_energy_conserving_where_documented():
    # Burley's diffuse (retro-reflection, not reduced by the specular Fresnel),
    # the sheen and the clearcoat are added on top of the rest: a white
    # material reflects more than it receives (values are Mitsuba's too, see
    # test_albedo_equals_mitsubas; measured with 400k samples).
    white_rough = {"base_color": WHITE, "roughness": 1.0}
    m0, _, _, _ = _albedo(white_rough, 0.0)
    m89, _, _, _ = _albedo(white_rough, 89.0)
    assert np.allclose(m0, 1.048, atol=0.01) and np.allclose(m89, 1.570, atol=0.015), (m0, m89)
    base, _, _, _ = _albedo({"base_color": WHITE}, 85.0)
    sheen, _, _, _ = _albedo({"base_color": WHITE, "sheen": 1.0}, 85.0)
    coat, _, _, _ = _albedo({"base_color": WHITE, "clearcoat": 1.0, "clearcoat_gloss": 1.0}, 0.0)
    base0, _, _, _ = _albedo({"base_color": WHITE}, 0.0)
    assert np.all(sheen > base + 0.05) and np.all(coat > base0 + 0.02), (base, sheen, base0, coat)
    # A mid-grey base with every reflection lobe on stays below 1.
    grey = {"base_color": (0.5, 0.5, 0.5), "sheen": 1.0, "clearcoat": 1.0, "roughness": 1.0}
    for theta in (0.0, 45.0, 80.0, 89.9):
        mean, _, _, _ = _albedo(grey, theta, n=100_000)
        assert np.all(mean < 1.0), (theta, mean)


def test_black_from_behind_without_transmission():
    for name in ("default", "metal", "clearcoat", "sheen"):
        p = pr.from_params(CASES[name])
        wi, wo = Array3f(0.3, 0.1, -0.9), Array3f(-0.3, 0.2, -0.9)
        wo2 = Array3f(-0.3, -0.1, 0.9)
        for w in (wo, wo2):
            assert np.all(np.array(pr.eval(p, wi, w)) == 0) and np.array(pr.pdf(p, wi, w))[0] == 0
        bs = pr.sample(p, wi, Float(0.3), Array2f(0.3, 0.7))
        assert not bool(bs.valid[0]) and np.all(np.array(bs.weight) == 0)
    p = pr.from_params(CASES["glass"])
    assert np.array(pr.eval(p, Array3f(0.3, 0.1, -0.9), Array3f(-0.3, -0.1, -0.9)))[0][0] > 0


# ---------------------------------------------------------------- extremes
EXTREME_WI = {
    "normal": (0.0, 0.0, 1.0),
    "grazing": (float(np.sqrt(1 - 1e-12)), 0.0, 1e-6),
    "grazing_inside": (float(np.sqrt(1 - 1e-12)), 0.0, -1e-6),
    "oblique_inside": tuple(float(x) for x in _dir_np(70.0, -1.0)),
    "normal_inside": (0.0, 0.0, -1.0),
}
EXTREME_MATERIALS = {
    "every_lobe": {k: v for k, v in CASES["all"].items() if k not in ("roughness", "eta")},
    "glass": {"spec_trans": 1.0},
    "metal": {"metallic": 1.0, "anisotropic": 1.0},
}


@pytest.mark.parametrize("material", list(EXTREME_MATERIALS))
def test_extremes_finite(material):
    # One launch: every (roughness, raw eta, wi) combination, 1000 samples each
    # (raw eta: also 1 with transmission, which derive() would make 1.001).
    combos = [(r, e, w) for r in (0.0, 0.01, 1.0) for e in (1.0, 1.001, 4.0, 0.5) for w in EXTREME_WI]
    k = 1000
    n = k * len(combos)
    rough = np.repeat([c[0] for c in combos], k).astype(np.float32)
    eta = np.repeat([c[1] for c in combos], k).astype(np.float32)
    wi_np = np.repeat(np.array([EXTREME_WI[c[2]] for c in combos]).T, k, axis=1).astype(np.float32)
    p = pr.from_params(EXTREME_MATERIALS[material])
    p.roughness, p.eta = Float(rough), Float(eta)
    p.clearcoat_gloss = dr.opaque(Float, 1.0, 1)  # the sharpest clearcoat
    wi = to_drpt(wi_np, Array3f)
    u = _uniform(n, 3, 31)
    one = 1 - 2**-24
    corners = np.array([[0, 0, one, 0.5, 0.99, 0.99], [0, one, 0, 0.5, 0, one], [0, one, one, 0, one, 0]])
    for i in range(len(combos)):
        u[:, i * k:i * k + 6] = corners
    bs = pr.sample(p, wi, Float(u[0]), Array2f(u[1], u[2]))
    w, pdf, valid, wo = np.array(bs.weight), np.array(bs.pdf), np.array(bs.valid), np.array(bs.wo)
    for a in (w, pdf, wo, np.array(bs.eta)):
        assert np.all(np.isfinite(a))
    assert np.all(w >= 0) and np.all(pdf >= 0)
    assert np.allclose(np.linalg.norm(wo, axis=0), 1.0, atol=1e-5)
    f = np.array(pr.eval(p, wi, bs.wo))
    assert np.all(np.isfinite(f)) and np.all(f >= 0)
    assert np.allclose(w[:, valid], f[:, valid] / pdf[valid], rtol=1e-5, atol=1e-30)
    assert np.all(w[:, ~valid] == 0) and np.all(pdf[~valid] == 0)
    assert valid.mean() > 0.2
    # eval/pdf of arbitrary wo per lane: uniform, grazing on both sides, wi's
    # mirror and straight-through directions, +-z
    g = EXTREME_WI["grazing"]
    wos = _sphere(n, 41)
    j = np.arange(n) % k
    for t, d in enumerate([(g[0], 0, g[2]), (-g[0], 0, g[2]), (-g[0], 0, -g[2]), (0, 0, 1), (0, 0, -1)]):
        wos[:, j == t] = np.array(d)[:, None]
    wos[:, j == 5] = (wi_np * np.array([[-1], [-1], [1]]))[:, j == 5]
    wos[:, j == 6] = -wi_np[:, j == 6]
    wos = wos.astype(np.float32)
    fe = np.array(pr.eval(p, wi, to_drpt(wos, Array3f)))
    pe = np.array(pr.pdf(p, wi, to_drpt(wos, Array3f)))
    assert np.all(np.isfinite(fe)) and np.all(fe >= 0)
    assert np.all(np.isfinite(pe)) and np.all(pe >= 0)


def test_zero_sampling_rates_are_not_nan():
    # metal with main_specular_sampling_rate 0: nothing can be sampled (Mitsuba: NaN).
    p = pr.from_params({"metallic": 1.0, "main_specular_sampling_rate": 0.0})
    wi = Array3f(0.3, 0.0, 0.95)
    wo = Array3f(-0.3, 0.0, 0.95)
    assert np.array(pr.pdf(p, wi, wo))[0] == 0 and np.array(pr.eval(p, wi, wo))[0][0] > 0
    bs = pr.sample(p, wi, Float(0.5), Array2f(0.5, 0.5))
    assert not bool(bs.valid[0]) and np.all(np.isfinite(np.array(bs.weight)))
