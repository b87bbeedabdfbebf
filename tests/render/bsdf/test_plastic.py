"""Plastic lobes (drpt/render/bsdf/plastic.py, roughplastic.py, and the numpy
coating quadrature roughplastic_tables.py) against Mitsuba 3's ``plastic``
and ``roughplastic`` plugins:

* derive: named IORs, errors, the specular sampling weight (rgb means and a
  bitmap's mean luminance) equal Mitsuba's;
* roughplastic's precomputed transmittance table and internal reflectance
  equal Mitsuba's (recovered from its eval, to ~1e-5);
* eval and pdf equal Mitsuba's on thousands of random pairs (incl. grazing
  and below the horizon), for several IORs (numbers and names), colors,
  nonlinear on/off, alphas, both distributions, sample_visible on/off;
  ``sample`` equals Mitsuba's for the same random numbers (both lobes);
* chi-square of ``sample`` against ``pdf`` at 0/45/80/89 degrees (plastic's
  Dirac samples are left out of the histogram, so it integrates to P_d, as
  the pdf does); negative controls (wrong alpha, a pdf off by a factor, a
  wrong IOR) are rejected;
* white furnace: albedo <= 1 (+ the documented tolerances);
* weight == eval / pdf on the smooth samples; finite, non-negative output at
  alpha 1e-4..1, IOR 1..4 (and 1/4), cos 1e-6; plastic's documented
  deviation from Mitsuba above eta = 2;
* params() through a stand-in table mixing distributions, sample_visible
  and nonlinear per lane equals the per-material results; through the real
  MaterialTable (textures, twosided, blendbsdf with plastic's Dirac part)
  eval/pdf equal Mitsuba's exported plugins and sampling is consistent; the
  table's table_lerp follows Mitsuba's lerp_gather;
* (slow) spheres of plastic / roughplastic rendered by drpt and Mitsuba agree.

Tolerances: eval/pdf to 2e-4 relative + 1e-6 absolute. The largest
differences are float32 Fresnel rounding where ``1 - F`` is small (cos <
1e-3) or near the critical angle (int_ior < ext_ior) and the tables' ~3e-6
(float32 sums in Mitsuba, float64 here); elsewhere they agree to ~1e-5.
Mitsuba's roughplastic ``pdf`` is *not* masked below the horizon (it returns
the specular term's value for ``wo.z < 0``, and for ``wi.z < 0`` when
``sample_visible`` is off); drpt returns 0 there, like both plugins' eval.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array2f, Array3f, Bool, Float, UInt32

from drpt.materials.bsdf_kinds import PARAMS
from drpt.render.bsdf import REGISTRY, lobe
from drpt.render.bsdf import plastic as pl
from drpt.render.bsdf import roughplastic as rp
from drpt.render.bsdf import roughplastic_tables as rt
from drpt.testing import mitsuba, spherical_chi2, to_drpt, to_mitsuba_float, to_mitsuba_vec3

COLOR = (0.8, 0.35, 0.1)
TINT = (0.9, 0.8, 1.0)


# ---------------------------------------------------------------- helpers
class FakeTable:
    """The material table's API as a lobe's ``params`` uses it (``value``,
    ``table_lerp``, ``specs_of``), over specs of one kind: each field is the
    spec's parameter (defaults filled in) or ``derive``'s output."""

    _TYPES = {"rgb": Array3f, "float": Float}

    def __init__(self, kind: str, params_list: list[dict]):
        self.kind = kind
        self.specs = [SimpleNamespace(kind=kind, params=dict(p)) for p in params_list]
        mod = lobe(kind)
        rows = [{**PARAMS[kind], **p, **mod.derive(p)} for p in params_list]
        self.cols, self.types = {}, {}
        for name, t in mod.FIELDS.items():
            vals = [r[name] for r in rows]
            if t == "rgb":
                a = np.array([np.broadcast_to(np.asarray(v, np.float64), (3,)) for v in vals], np.float32)
                self.cols[name] = Array3f(*(Float(np.ascontiguousarray(a[:, i])) for i in range(3)))
            elif t == "float":
                self.cols[name] = Float(np.array([float(v) for v in vals], np.float32))
            else:
                assert t[0] == "table" and all(np.asarray(v).shape == (t[1],) for v in vals)
                self.cols[name] = Float(np.concatenate(vals).astype(np.float32))
            self.types[name] = t

    def value(self, name, si, active):
        t = self.types[name]
        return dr.gather(self._TYPES[t], self.cols[name], si.material, active)

    def table_lerp(self, name, si, x, active):
        """Mitsuba's ``lerp_gather`` (x (N-1), index clamped to N-2, linear)."""
        n = self.types[name][1]
        x = Float(x) * float(n - 1)
        i = dr.minimum(UInt32(dr.maximum(x, 0.0)), n - 2)
        j = si.material * n + i
        v0 = dr.gather(Float, self.cols[name], j, active)
        v1 = dr.gather(Float, self.cols[name], j + 1, active)
        return dr.lerp(v0, v1, x - Float(i))

    def specs_of(self, kind):
        return [s for s in self.specs if s.kind == kind]


def _params(kind: str, n: int, materials=None, **prm):
    """A lobe's params record for ``n`` lanes of one material (or ``materials``
    = (list of param dicts, per-lane material index))."""
    if materials is None:
        table = FakeTable(kind, [prm])
        ids = np.zeros(n, np.uint32)
    else:
        plist, ids = materials
        table = FakeTable(kind, plist)
    si = SimpleNamespace(material=UInt32(np.asarray(ids, np.uint32)))
    return lobe(kind).params(table, si, dr.full(Bool, True, n))


def _mi_dict(kind: str, prm: dict) -> dict:
    d = {"type": kind}
    for k, v in prm.items():
        if isinstance(v, tuple):
            d[k] = {"type": "rgb", "value": list(v)}
        else:
            d[k] = v
    return d


def _sphere(n, seed):
    v = np.random.default_rng(seed).normal(size=(3, n))
    return v / np.linalg.norm(v, axis=0)


def _with_z(v, z):
    """``v`` (3, n) turned to have cosine ``z`` (same azimuth)."""
    z = np.broadcast_to(np.asarray(z, np.float64), (v.shape[1],))
    r = np.hypot(v[0], v[1])
    r = np.where(r > 0, r, 1.0)
    s = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    return np.array([v[0] / r * s, v[1] / r * s, z])


def _pairs(n=20_000, seed=0):
    """Random (wi, wo) over the sphere, with grazing cosines and, for the
    rough lobe, directions at and near the specular peak."""
    wi, wo = _sphere(n, seed), _sphere(n, seed + 1)
    k = n // 10
    graze = np.array([1e-6, 1e-4, 1e-3, 1e-2, 0.0, -1e-6])
    wi[:, :k] = _with_z(wi[:, :k], np.resize(graze, k))
    wo[:, k:2 * k] = _with_z(wo[:, k:2 * k], np.resize(graze, k))
    # at / near the mirror direction
    mirror = np.array([-wi[0], -wi[1], wi[2]])
    wo[:, 2 * k:3 * k] = mirror[:, 2 * k:3 * k]
    near = mirror[:, 3 * k:4 * k] + 0.05 * _sphere(k, seed + 2)
    wo[:, 3 * k:4 * k] = near / np.linalg.norm(near, axis=0)
    return wi.astype(np.float32), wo.astype(np.float32)


def _close(a, b, rtol=2e-4, atol=1e-6):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    bad = ~(np.abs(a - b) <= atol + rtol * np.abs(b))
    assert not bad.any(), f"{bad.sum()} of {bad.size} differ, e.g. {a[bad][:4]} vs {b[bad][:4]}"


def _mi_eval_pdf(mi, kind, prm, wi, wo):
    b = mi.load_dict(_mi_dict(kind, prm))
    si = dr.zeros(mi.SurfaceInteraction3f, wi.shape[1])
    si.wi = to_mitsuba_vec3(wi)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    ctx = mi.BSDFContext()
    mwo = to_mitsuba_vec3(wo)
    return np.array(b.eval(ctx, si, mwo)), np.array(b.pdf(ctx, si, mwo)), b


def _eval_pdf(kind, prm, wi, wo):
    p = _params(kind, wi.shape[1], **prm)
    mod = lobe(kind)
    return (np.array(mod.eval(p, to_drpt(wi, Array3f), to_drpt(wo, Array3f))),
            np.array(mod.pdf(p, to_drpt(wi, Array3f), to_drpt(wo, Array3f))))


def _sample(kind, prm, wi, u):
    p = _params(kind, wi.shape[1], **prm)
    bs = lobe(kind).sample(p, to_drpt(wi, Array3f), to_drpt(u[0], Float), to_drpt(u[1:], Array2f))
    n = wi.shape[1]
    return {k: np.broadcast_to(np.array(getattr(bs, k)), (3, n) if k in ("wo", "weight") else (n,))
            for k in ("wo", "weight", "pdf", "valid", "delta", "eta")}


def _dir(theta_deg, phi_deg=0.0):
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])


def _chi2(kind, prm, theta, sample_count=200_000, res=61, ires=16, pdf_scale=1.0, pdf_prm=None):
    """Mitsuba's ChiSquareTest of ``sample`` (3 random dimensions; Dirac and
    invalid samples weigh 0) against ``pdf`` (times ``pdf_scale``, with
    ``pdf_prm`` for a negative control). Returns (passed, messages)."""
    mitsuba()

    wi1 = _dir(theta, 30.0).astype(np.float32)
    mod = lobe(kind)
    p_pdf = pdf_prm if pdf_prm is not None else prm

    def sample_func(u):
        u = np.array(u, np.float32)
        n = u.shape[1]
        wi = np.repeat(wi1[:, None], n, axis=1)
        s = _sample(kind, prm, wi, u)
        w = (s["valid"] & ~s["delta"]).astype(np.float32)
        return to_mitsuba_vec3(s["wo"]), to_mitsuba_float(w)

    def pdf_func(wo):
        wo = np.array(wo, np.float32)
        n = wo.shape[1]
        wi = np.repeat(wi1[:, None], n, axis=1)
        p = _params(kind, n, **p_pdf)
        v = np.array(mod.pdf(p, to_drpt(wi, Array3f), to_drpt(wo, Array3f))) * pdf_scale
        return to_mitsuba_float(v)

    return spherical_chi2(sample_func, pdf_func, sample_dim=3, sample_count=sample_count, res=res, ires=ires, seed=3)


def _hemisphere(n_theta=400, n_phi=128):
    """Midpoint quadrature of the upper hemisphere in (cos theta, phi)."""
    c = (np.arange(n_theta) + 0.5) / n_theta
    phi = (np.arange(n_phi) + 0.5) / n_phi * 2 * np.pi
    C, P = np.meshgrid(c, phi, indexing="ij")
    s = np.sqrt(1 - C * C)
    d = np.array([s * np.cos(P), s * np.sin(P), C]).reshape(3, -1)
    return d.astype(np.float32), np.full(d.shape[1], 2 * np.pi / (n_theta * n_phi))


# ================================================================ derive
def test_registered_and_fields_complete():
    assert REGISTRY["plastic"] == "plastic" and REGISTRY["roughplastic"] == "roughplastic"
    for kind in ("plastic", "roughplastic"):
        mod = lobe(kind)
        out = mod.derive({})
        for name in mod.FIELDS:
            assert name in out or name in PARAMS[kind], name
        assert mod.COLOR == "diffuse_reflectance" and mod.COLOR in mod.FIELDS
    assert not pl.DELTA and not rp.DELTA


def test_named_iors_and_errors():
    d = pl.derive({})  # polypropylene / air
    assert d["plastic_eta"] == pytest.approx(1.49 / 1.000277)
    assert pl.derive({"int_ior": "Diamond", "ext_ior": "water"})["plastic_eta"] == pytest.approx(2.419 / 1.333)
    assert pl.derive({"int_ior": 1.7, "ext_ior": 1.0})["plastic_eta"] == pytest.approx(1.7)
    for bad in ("unobtainium", -1.0, 0.0, float("nan"), None, True):
        with pytest.raises(ValueError):
            pl.derive({"int_ior": bad})
    with pytest.raises(ValueError):
        pl.derive({"nonlinear": "maybe"})
    assert pl.derive({"nonlinear": "true"})["plastic_nonlinear"] == 1.0
    with pytest.raises(ValueError, match="differ"):
        rp.derive({"int_ior": 1.3, "ext_ior": 1.3})
    with pytest.raises(ValueError, match="anisotropic"):
        rp.derive({"alpha_u": 0.1, "alpha_v": 0.2})
    with pytest.raises(ValueError, match="distribution"):
        rp.derive({"distribution": "phong"})
    with pytest.raises(ValueError):
        rp.derive({"alpha": -0.1})
    assert rp.derive({"alpha": 0.0})["alpha"] == pytest.approx(1e-4)


def _mi_sampling_weight(b) -> float:
    line = [x for x in str(b).splitlines() if "specular_sampling_weight" in x][0]
    return float(line.split("=")[1].strip().rstrip(",").strip("[]"))


@pytest.mark.mitsuba
def test_specular_sampling_weight_equals_mitsuba(tmp_path):
    """w = mean(ks) / (mean(kd) + mean(ks)): rgb channel means, a bitmap's mean luminance."""
    mi = mitsuba()
    from PIL import Image

    img = np.random.default_rng(4).integers(0, 256, (6, 5, 3), dtype=np.uint8)
    path = tmp_path / "kd.png"
    Image.fromarray(img).save(path)
    tex = SimpleNamespace(path=path)
    cases = [({}, {}),
             ({"diffuse_reflectance": COLOR, "specular_reflectance": TINT},) * 2,
             ({"diffuse_reflectance": 0.25}, {"diffuse_reflectance": 0.25}),
             ({"diffuse_reflectance": tex, "specular_reflectance": (0.3, 0.2, 0.1)},
              {"diffuse_reflectance": {"type": "bitmap", "filename": str(path)},
               "specular_reflectance": (0.3, 0.2, 0.1)})]
    for ours, theirs in cases:
        for kind in ("plastic", "roughplastic"):
            b = mi.load_dict(_mi_dict(kind, theirs))
            w = lobe(kind).derive(ours)["plastic_specular_weight"]
            assert w == pytest.approx(_mi_sampling_weight(b), rel=1e-5), (kind, ours)


def test_fdr_internal():
    # Mitsuba's fit for eta <= 2, the exact relation above; white plastic conserves energy
    assert pl.internal_fdr(1.49) == pytest.approx(pl.fresnel_diffuse_reflectance(1 / 1.49))
    for eta in (2.5, 3.0, 4.0):
        assert pl.internal_fdr(eta) < 1.0
        assert pl.fresnel_diffuse_reflectance(1 / eta) > pl.internal_fdr(eta)  # Mitsuba's overshoots
    assert pl.fresnel_diffuse_reflectance(1 / 4.0) > 1.0  # hence Mitsuba's negative values
    # continuity at the switch: 1 / (1 - Fdr) changes by < 0.1 %
    lo, hi = pl.internal_fdr(2.0), pl.internal_fdr(2.0 + 1e-9)
    assert abs((1 - lo) / (1 - hi) - 1) < 1e-3


# ================================================================ tables
@pytest.mark.mitsuba
@pytest.mark.parametrize("distr,alpha,eta", [("beckmann", 0.1, 1.49), ("ggx", 0.02, 2.5),
                                             pytest.param("ggx", 0.3, 1.49, marks=pytest.mark.slow),
                                             pytest.param("beckmann", 0.6, 0.7, marks=pytest.mark.slow)])
def test_tables_equal_mitsuba(distr, alpha, eta):
    """Recover Mitsuba's T(mu_j) and R_int from its eval (nonlinear, specular
    off, wi = normal, wo at the table's cosines) and compare with the numpy
    quadrature."""
    mi = mitsuba()
    mu = rt.table_mu()
    wo = np.array([np.sqrt(1 - mu ** 2), 0 * mu, mu], np.float32)
    wi = np.repeat(np.array([[0.0], [0.0], [1.0]], np.float32), mu.size, axis=1)
    vals = {}
    for a in (0.25, 0.75):
        prm = {"distribution": distr, "alpha": alpha, "int_ior": eta, "ext_ior": 1.0, "nonlinear": True,
               "diffuse_reflectance": (a, a, a), "specular_reflectance": (0.0, 0.0, 0.0)}
        vals[a] = _mi_eval_pdf(mi, "roughplastic", prm, wi, wo)[0][0].astype(np.float64)
    # v_a = a / (1 - a R) K  ->  R from the ratio, then K = T(1) T(mu) mu / (pi eta^2)
    q3 = 3.0 * vals[0.25][-1] / vals[0.75][-1]
    r_int = (1.0 - q3) / (0.75 - 0.25 * q3)
    k = vals[0.25] * (1.0 - 0.25 * r_int) / 0.25 / (mu / np.pi / eta ** 2)
    t_mi = k / np.sqrt(k[-1])
    t, r = rt.coating_tables(distr == "beckmann", alpha, eta)
    assert r == pytest.approx(r_int, abs=1e-5)
    _close(t[1:], t_mi[1:], rtol=5e-5, atol=1e-5)
    assert np.all((t >= 0) & (t <= 1)) and 0 <= r < 1


def test_table_lerp_convention():
    """The material table reads the transmittance table as Mitsuba's
    lerp_gather: x (N-1), index clamped to N-2, linear in between."""
    from drpt.materials.spec import BSDFSpec, complete
    from drpt.render.material import MaterialTable

    specs = [complete(BSDFSpec("roughplastic", {"alpha": 0.3, "distribution": "ggx"})),
             complete(BSDFSpec("roughplastic", {"alpha": 0.05, "int_ior": 1.0, "ext_ior": 1.6}))]
    table = MaterialTable(_scene(specs))
    x = np.array([0.0, 1e-7, 0.5, 1.0 / 63, 0.3217, 0.99, 1.0 - 1e-7, 1.0], np.float32)
    for m, spec in enumerate(specs):
        data = rp.derive(spec.params)[rp.TABLE].astype(np.float32)
        si = SimpleNamespace(material=UInt32(np.full(x.size, m, np.uint32)))
        got = np.array(table.at(si.material).table_lerp(rp.TABLE, si, Float(x), dr.full(Bool, True, x.size)))
        xs = x.astype(np.float64) * 63
        i = np.minimum(xs.astype(int), 62)
        want = data[i] + (data[i + 1] - data[i]) * (xs - i)
        np.testing.assert_allclose(got, want, rtol=2e-6, atol=1e-9)


# ================================================================ eval/pdf vs Mitsuba
PLASTIC_CASES = [
    {},  # polypropylene / air, gray
    {"int_ior": "bk7", "ext_ior": "air", "diffuse_reflectance": COLOR, "specular_reflectance": TINT},
    {"int_ior": 1.2, "ext_ior": 1.0, "diffuse_reflectance": (1.0, 1.0, 1.0), "nonlinear": True},
    {"int_ior": 1.9, "ext_ior": 1.0, "diffuse_reflectance": COLOR, "nonlinear": True},
    {"int_ior": 1.0, "ext_ior": 1.0},
    {"int_ior": 1.0, "ext_ior": 1.4, "diffuse_reflectance": COLOR},  # eta < 1
]


@pytest.mark.mitsuba
@pytest.mark.parametrize("prm", PLASTIC_CASES, ids=range(len(PLASTIC_CASES)))
def test_plastic_eval_pdf_equal_mitsuba(prm):
    mi = mitsuba()
    wi, wo = _pairs()
    f_m, p_m, _ = _mi_eval_pdf(mi, "plastic", prm, wi, wo)
    f, p = _eval_pdf("plastic", prm, wi, wo)
    _close(f, f_m)
    _close(p, p_m)
    both = (wi[2] > 0) & (wo[2] > 0)
    assert np.all(f[:, ~both] == 0) and np.all(p[~both] == 0)
    assert both.sum() > 4000 and np.count_nonzero(f[0, both]) > 500  # (TIR zeroes some when eta < 1)


@pytest.mark.mitsuba
@pytest.mark.parametrize("prm", PLASTIC_CASES[:4] + PLASTIC_CASES[5:], ids=[0, 1, 2, 3, 5])
def test_plastic_sample_equals_mitsuba(prm):
    """The same (u1, u2) give Mitsuba's direction, weight, lobe and (smooth) pdf."""
    mi = mitsuba()
    n = 20_000
    wi = _pairs(n, 7)[0]
    u = np.random.default_rng(8).random((3, n)).astype(np.float32)
    s = _sample("plastic", prm, wi, u)
    b = mi.load_dict(_mi_dict("plastic", prm))
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = to_mitsuba_vec3(wi)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    bs, w = b.sample(mi.BSDFContext(), si, mi.Float(u[0]), mi.Point2f(u[1], u[2]))
    w_m = np.array(w)
    delta_m = np.array(bs.sampled_type) == int(mi.BSDFFlags.DeltaReflection)
    front = wi[2] > 0
    assert np.array_equal(s["delta"][front], delta_m[front]) and not s["delta"][~front].any()
    assert np.all(s["weight"][:, ~front] == 0) and not s["valid"][~front].any()
    np.testing.assert_allclose(s["wo"][:, front], np.array(bs.wo)[:, front], atol=1e-5)
    _close(s["weight"][:, front], w_m[:, front], rtol=1e-3, atol=1e-5)
    smooth = front & ~delta_m
    _close(s["pdf"][smooth], np.array(bs.pdf)[smooth])
    assert np.all(s["pdf"][s["delta"]] == 0)  # drpt's convention (Mitsuba: P_s)
    assert np.all(s["eta"] == 1.0)


ROUGH_CASES = [
    {},  # beckmann 0.1, polypropylene / air
    {"distribution": "ggx", "alpha": 0.3, "int_ior": 1.9, "ext_ior": 1.0, "diffuse_reflectance": COLOR,
     "specular_reflectance": TINT, "nonlinear": True},
    {"distribution": "ggx", "alpha": 0.02, "int_ior": "bk7", "diffuse_reflectance": (1.0, 1.0, 1.0),
     "sample_visible": False},
    {"distribution": "beckmann", "alpha": 0.7, "int_ior": 1.0, "ext_ior": 1.4, "diffuse_reflectance": COLOR,
     "sample_visible": False},
    {"distribution": "ggx", "alpha": 1.0, "int_ior": 4.0, "ext_ior": 1.0, "nonlinear": True},
    {"distribution": "beckmann", "alpha": 0.01, "int_ior": 1.33, "ext_ior": 1.0, "specular_reflectance": TINT},
]


@pytest.mark.mitsuba
@pytest.mark.parametrize("prm", ROUGH_CASES, ids=range(len(ROUGH_CASES)))
def test_roughplastic_eval_pdf_equal_mitsuba(prm):
    mi = mitsuba()
    wi, wo = _pairs()
    f_m, p_m, _ = _mi_eval_pdf(mi, "roughplastic", prm, wi, wo)
    f, p = _eval_pdf("roughplastic", prm, wi, wo)
    _close(f, f_m)
    both = (wi[2] > 0) & (wo[2] > 0)
    # Mitsuba's pdf is unmasked outside the hemisphere (see the module docs)
    _close(p[both], p_m[both])
    assert np.all(f[:, ~both] == 0) and np.all(p[~both] == 0)
    assert np.count_nonzero(f[0, both]) > 500 and np.count_nonzero(p[both]) > 0.9 * both.sum()


@pytest.mark.mitsuba
@pytest.mark.parametrize("prm", ROUGH_CASES, ids=range(len(ROUGH_CASES)))
def test_roughplastic_sample_equals_mitsuba(prm):
    """The same (u1, u2) give Mitsuba's lobe choice, direction, weight and
    pdf (the microfacet samplers are Mitsuba's, :mod:`.microfacet`). With
    ``sample_visible = False`` drpt computes sin(theta_m) from tan(theta_m)
    where Mitsuba takes sqrt(1 - cos^2) in float32, so its normals differ by
    up to ~5e-4 at small alphas (sharp lobes then magnify weight
    differences): looser bounds there."""
    mi = mitsuba()
    n = 20_000
    wi = _pairs(n, 7)[0]
    u = np.random.default_rng(8).random((3, n)).astype(np.float32)
    s = _sample("roughplastic", prm, wi, u)
    b = mi.load_dict(_mi_dict("roughplastic", prm))
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = to_mitsuba_vec3(wi)
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    bs, w = b.sample(mi.BSDFContext(), si, mi.Float(u[0]), mi.Point2f(u[1], u[2]))
    w_m, wo_m, p_m = np.array(w), np.array(bs.wo), np.array(bs.pdf)
    valid_m = np.any(w_m != 0, axis=0)
    front = wi[2] > 0
    assert not s["valid"][~front].any() and not s["delta"].any()
    assert (s["valid"][front] == valid_m[front]).mean() > 0.999
    ok = front & s["valid"] & valid_m
    err = np.linalg.norm(s["wo"] - wo_m, axis=0)[ok]
    rel_w = (np.abs(s["weight"] - w_m).max(axis=0) / np.maximum(np.abs(w_m).max(axis=0), 1e-6))[ok]
    rel_p = np.abs(s["pdf"][ok] / p_m[ok] - 1.0)
    visible = prm.get("sample_visible", True)
    assert err.max() < (1e-4 if visible else 2e-3), err.max()
    assert np.quantile(rel_w, 0.999) < (1e-3 if visible else 2e-2) and np.quantile(rel_p, 0.999) < 1e-2
    assert np.median(rel_w) < 1e-4


# ================================================================ deviations
@pytest.mark.mitsuba
@pytest.mark.parametrize("eta", [3.0, 4.0])
def test_plastic_above_eta_2_is_mitsuba_with_exact_fdr(eta):
    """The documented deviation: Mitsuba's diffuse part is drpt's times (1 - Fdr_drpt) / (1 - Fdr_M)."""
    mi = mitsuba()
    prm = {"int_ior": eta, "ext_ior": 1.0, "diffuse_reflectance": COLOR}
    wi, wo = _pairs(4000, 3)
    f_m, _, _ = _mi_eval_pdf(mi, "plastic", prm, wi, wo)
    f, _ = _eval_pdf("plastic", prm, wi, wo)
    ratio = (1 - pl.internal_fdr(eta)) / (1 - pl.fresnel_diffuse_reflectance(1 / eta))
    _close(f * ratio, f_m, rtol=1e-3, atol=1e-6)
    assert np.all(f >= 0) and np.isfinite(f).all()
    if eta == 4.0:
        assert (f_m < 0).any()  # Mitsuba's value is negative here


# ================================================================ negative controls
@pytest.mark.mitsuba
def test_negative_control_equivalence():
    """The comparison catches a 1% IOR error (plastic) and a 10% alpha error (roughplastic)."""
    mi = mitsuba()
    wi, wo = _pairs(4000, 5)
    f_m, _, _ = _mi_eval_pdf(mi, "plastic", {"int_ior": 1.5, "ext_ior": 1.0}, wi, wo)
    f, _ = _eval_pdf("plastic", {"int_ior": 1.515, "ext_ior": 1.0}, wi, wo)
    with pytest.raises(AssertionError):
        _close(f, f_m)
    f_m, p_m, _ = _mi_eval_pdf(mi, "roughplastic", {"alpha": 0.2}, wi, wo)
    f, p = _eval_pdf("roughplastic", {"alpha": 0.22}, wi, wo)
    with pytest.raises(AssertionError):
        _close(f, f_m)
    both = (wi[2] > 0) & (wo[2] > 0)
    with pytest.raises(AssertionError):
        _close(p[both], p_m[both])


@pytest.mark.mitsuba
@pytest.mark.slow
def test_negative_control_chi2():
    """chi-square rejects a pdf with a wrong alpha, a pdf 3% too large, a
    plastic pdf with the wrong lobe probability."""
    ok, _ = _chi2("roughplastic", {"distribution": "ggx", "alpha": 0.3}, 45.0,
                  pdf_prm={"distribution": "ggx", "alpha": 0.35})
    assert not ok
    ok, _ = _chi2("roughplastic", {"alpha": 0.3}, 45.0, pdf_scale=1.03)
    assert not ok
    ok, _ = _chi2("plastic", {"diffuse_reflectance": COLOR}, 45.0,
                  pdf_prm={"diffuse_reflectance": COLOR, "specular_reflectance": (0.6, 0.6, 0.6)})
    assert not ok


# ================================================================ chi-square
@pytest.mark.mitsuba
@pytest.mark.parametrize("theta", [0.0, 45.0, 80.0, 89.0])
def test_plastic_chi2(theta):
    ok, msg = _chi2("plastic", {"diffuse_reflectance": COLOR, "specular_reflectance": TINT}, theta)
    assert ok, msg


# (params, id, angles). Sharp lobes are not tested at 89 degrees: their
# reflection lobe peaks within ~1 degree of the horizon and the test's pdf
# integration (res 61, 16x16 trapezoid per cell) misses the peak by several
# percent (for alpha 0.1 even at res 101), while a fine quadrature of the same
# pdf converges to the fraction of valid samples.
CHI2_ROUGH = [({"distribution": "ggx", "alpha": 0.3}, "ggx-0.3", (0.0, 45.0, 80.0, 89.0)),
              ({"distribution": "beckmann", "alpha": 0.1, "diffuse_reflectance": COLOR}, "beckmann-0.1",
               (0.0, 45.0, 80.0)),
              ({"distribution": "beckmann", "alpha": 0.5}, "beckmann-0.5", (89.0,))]
CHI2_ROUGH_SLOW = [({"distribution": "ggx", "alpha": 0.05, "sample_visible": False}, "ggx-0.05-all",
                    (0.0, 45.0, 80.0)),
                   ({"distribution": "beckmann", "alpha": 0.8, "int_ior": 1.0, "ext_ior": 1.4,
                     "sample_visible": False}, "beckmann-0.8-all-eta<1", (0.0, 45.0, 80.0, 89.0)),
                   ({"distribution": "ggx", "alpha": 0.4, "int_ior": 4.0, "ext_ior": 1.0, "nonlinear": True,
                     "specular_reflectance": TINT, "diffuse_reflectance": COLOR}, "ggx-0.4-eta4", (45.0, 89.0))]


def _expand(cases):
    return [pytest.param(c[0], t, id=f"{c[1]}-{t:g}") for c in cases for t in c[2]]


@pytest.mark.mitsuba
@pytest.mark.parametrize("prm,theta", _expand(CHI2_ROUGH))
def test_roughplastic_chi2(prm, theta):
    ok, msg = _chi2("roughplastic", prm, theta)
    assert ok, msg


@pytest.mark.mitsuba
@pytest.mark.slow
@pytest.mark.parametrize("prm,theta", _expand(CHI2_ROUGH_SLOW))
def test_roughplastic_chi2_more(prm, theta):
    ok, msg = _chi2("roughplastic", prm, theta)
    assert ok, msg


# ================================================================ energy
def _albedo(kind, prm, theta, n=200_000):
    """(quadrature of eval over the hemisphere + the Dirac part's F k_s, MC mean of the weights)."""
    d, dw = _hemisphere()
    wi1 = _dir(theta, 20.0).astype(np.float32)
    wi = np.repeat(wi1[:, None], d.shape[1], axis=1)
    f, _ = _eval_pdf(kind, prm, wi, d)
    quad = (f.astype(np.float64) * dw).sum(axis=1)
    u = np.random.default_rng(11).random((3, n)).astype(np.float32)
    s = _sample(kind, prm, np.repeat(wi1[:, None], n, axis=1), u)
    mc = s["weight"].astype(np.float64).mean(axis=1)
    if kind == "plastic":
        p = _params(kind, 1, **prm)
        f_i = np.array(pl.fresnel(Float(float(wi1[2])), p.eta))
        quad = quad + f_i * np.array(p.specular)[:, 0]
    return quad, mc


def _quick(cases, quick):
    """``cases`` as params, those not in ``quick`` marked slow."""
    return [c if c in quick else pytest.param(*c, marks=pytest.mark.slow) for c in cases]


@pytest.mark.parametrize("eta,theta", _quick([(e, t) for e in (1.0, 1.49, 2.0, 3.0, 4.0) for t in (0.0, 60.0, 85.0)],
                                             [(1.0, 0.0), (1.49, 60.0), (2.0, 85.0), (4.0, 0.0)]))
def test_plastic_furnace(eta, theta):
    """White plastic: albedo 1 to the fit's accuracy (<= 1.003); the MC mean of the sampled weights agrees."""
    prm = {"int_ior": eta, "ext_ior": 1.0, "diffuse_reflectance": (1.0, 1.0, 1.0)}
    quad, mc = _albedo("plastic", prm, theta)
    assert np.all(quad <= 1.003) and np.all(quad > 0.98), quad
    np.testing.assert_allclose(mc, quad, rtol=5e-3)
    # nonlinear with a white base is the same model (rho' = 1 / (1 - Fdr))
    quad_nl, _ = _albedo("plastic", {**prm, "nonlinear": True}, theta, n=10)
    np.testing.assert_allclose(quad_nl, quad, rtol=1e-6)


def _mi_albedo(kind, prm, theta, n=200_000):
    """Mitsuba's directional albedo (mean sample weight) and its standard error."""
    mi = mitsuba()
    b = mi.load_dict(_mi_dict(kind, prm))
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = to_mitsuba_vec3(np.repeat(_dir(theta, 20.0)[:, None], n, axis=1).astype(np.float32))
    u = np.random.default_rng(5).random((3, n)).astype(np.float32)
    _, w = b.sample(mi.BSDFContext(), si, mi.Float(u[0]), mi.Point2f(u[1], u[2]))
    w = np.array(w, np.float64)
    return w.mean(axis=1), w.std(axis=1) / math.sqrt(n)


@pytest.mark.mitsuba
@pytest.mark.parametrize("distr,alpha,theta", _quick(
    [(d, a, t) for d, a in (("beckmann", 0.1), ("ggx", 0.3), ("ggx", 1.0), ("beckmann", 0.01))
     for t in (0.0, 60.0, 85.0)],
    [("beckmann", 0.1, 60.0), ("ggx", 0.3, 85.0), ("ggx", 1.0, 0.0), ("beckmann", 0.01, 0.0)]))
def test_roughplastic_furnace(distr, alpha, theta):
    """White rough plastic: the albedo (mean of the sampled weights) is <= 1
    and equals Mitsuba's (its mean sample weight, independent samples) to 5
    standard errors. The model loses energy (single-scattering microfacets:
    0.97 at alpha 0.1, 0.34 for GGX at alpha 1, normal incidence). Where the
    quadrature grid resolves the lobe (alpha >= 0.3) the albedo also equals
    the quadrature of eval."""
    prm = {"distribution": distr, "alpha": alpha, "diffuse_reflectance": (1.0, 1.0, 1.0)}
    quad, mc = _albedo("roughplastic", prm, theta)
    assert np.all(mc <= 1.0), mc
    ref, err = _mi_albedo("roughplastic", prm, theta)
    assert np.all(np.abs(mc - ref) < 5.0 * err * math.sqrt(2.0) + 1e-6), (mc, ref, err)
    if alpha >= 0.3:
        np.testing.assert_allclose(mc, quad, rtol=2e-3)


# ================================================================ weights, extremes
@pytest.mark.parametrize("kind,prm", [("plastic", {"diffuse_reflectance": COLOR, "nonlinear": True}),
                                      ("roughplastic", ROUGH_CASES[1]), ("roughplastic", ROUGH_CASES[3]),
                                      ("roughplastic", {})])
def test_weight_is_eval_over_pdf(kind, prm):
    n = 20_000
    wi = _pairs(n, 12)[0]
    u = np.random.default_rng(13).random((3, n)).astype(np.float32)
    s = _sample(kind, prm, wi, u)
    smooth = s["valid"] & ~s["delta"]
    assert smooth.sum() > n // 4
    f, p = _eval_pdf(kind, prm, wi[:, smooth], s["wo"][:, smooth].astype(np.float32))
    _close(p, s["pdf"][smooth], rtol=1e-5, atol=0)
    _close(s["weight"][:, smooth], f / p, rtol=1e-5, atol=1e-7)
    assert np.all(s["wo"][2][smooth] > 0) and not s["valid"][wi[2] <= 0].any()
    if kind == "roughplastic":
        assert not s["delta"].any()


EXTREME_U = np.array([[0.0, 1 - 6e-8, 0.5, 0.999, 1e-7],
                      [0.0, 1 - 6e-8, 0.5, 1e-7, 0.999],
                      [0.0, 1 - 6e-8, 0.5, 0.999, 1e-7]], np.float32)


def _extreme_inputs():
    cosines = np.array([1.0, 0.5, 1e-2, 1e-4, 1e-6, 0.0, -1e-6, -0.5], np.float64)
    ws = np.array([[np.sqrt(1 - c * c), 0.0, c] for c in cosines]).T
    wi = np.repeat(ws, ws.shape[1], axis=1).astype(np.float32)
    wo = np.tile(ws, ws.shape[1]).astype(np.float32)
    n = wi.shape[1]
    u = np.tile(EXTREME_U, (1, 1 + n // EXTREME_U.shape[1]))[:, :n]
    u = np.concatenate([u, np.random.default_rng(2).random((3, n)).astype(np.float32)], axis=1)
    return np.concatenate([wi, wi], axis=1), np.concatenate([wo, wo], axis=1), u


def _check_finite(kind, prm):
    wi, wo, u = _extreme_inputs()
    for kd, nl in (((1.0, 1.0, 1.0), True), ((0.0, 0.0, 0.0), False)):
        q = {**prm, "diffuse_reflectance": kd, "nonlinear": nl}
        f, p = _eval_pdf(kind, q, wi, wo)
        s = _sample(kind, q, wi, u)
        for name, v in (("eval", f), ("pdf", p), ("weight", s["weight"]), ("spdf", s["pdf"]), ("wo", s["wo"])):
            assert np.isfinite(v).all(), (name, q)
            if name != "wo":
                assert (v >= 0).all(), (name, q)


IORS = [(1.0, 1.0), (1.0001, 1.0), (4.0, 1.0), (1.0, 4.0), ("polypropylene", "air")]


@pytest.mark.parametrize("ior", IORS, ids=[f"{a}-{b}" for a, b in IORS])
def test_plastic_extremes_finite(ior):
    _check_finite("plastic", {"int_ior": ior[0], "ext_ior": ior[1]})


ROUGH_EXTREMES = [("beckmann", 1e-4, (4.0, 1.0)), ("ggx", 1e-4, (1.0, 4.0)), ("ggx", 1.0, (1.0001, 1.0)),
                  ("beckmann", 1.0, (1.0, 4.0))]


@pytest.mark.parametrize("case", ROUGH_EXTREMES, ids=[f"{c[0]}-{c[1]}-{c[2][0]}-{c[2][1]}" for c in ROUGH_EXTREMES])
def test_roughplastic_extremes_finite(case):
    distr, alpha, (ii, ei) = case
    _check_finite("roughplastic", {"distribution": distr, "alpha": alpha, "int_ior": ii, "ext_ior": ei,
                                   "sample_visible": alpha < 1.0})


@pytest.mark.slow
@pytest.mark.parametrize("distr", ["beckmann", "ggx"])
@pytest.mark.parametrize("alpha", [1e-4, 1e-3, 1.0])
def test_roughplastic_extremes_finite_sweep(distr, alpha):
    for ii, ei in IORS[1:]:
        for vis in (True, False):
            _check_finite("roughplastic", {"distribution": distr, "alpha": alpha, "int_ior": ii, "ext_ior": ei,
                                           "sample_visible": vis})


# ================================================================ per-lane params
def test_params_mixed_materials_per_lane():
    """One table with materials mixing Beckmann/GGX, sample_visible on/off,
    nonlinear on/off: every lane equals its material evaluated alone."""
    mats = [ROUGH_CASES[0], ROUGH_CASES[1], ROUGH_CASES[2], ROUGH_CASES[3]]
    n = 8000
    wi, wo = _pairs(n, 21)
    ids = np.arange(n) % len(mats)
    p = _params("roughplastic", n, materials=(mats, ids))
    assert not isinstance(p.beckmann, bool) and not isinstance(p.visible, bool)
    dwi, dwo = to_drpt(wi, Array3f), to_drpt(wo, Array3f)
    f, pd = np.array(rp.eval(p, dwi, dwo)), np.array(rp.pdf(p, dwi, dwo))
    u = np.random.default_rng(22).random((3, n)).astype(np.float32)
    s = rp.sample(p, dwi, to_drpt(u[0], Float), to_drpt(u[1:], Array2f))
    s_w = np.array(s.weight)
    for k, prm in enumerate(mats):
        sel = ids == k
        f_k, p_k = _eval_pdf("roughplastic", prm, wi[:, sel], wo[:, sel])
        np.testing.assert_allclose(f[:, sel], f_k, rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(pd[sel], p_k, rtol=1e-6, atol=1e-9)
        s_k = _sample("roughplastic", prm, wi[:, sel], u[:, sel])
        np.testing.assert_allclose(s_w[:, sel], s_k["weight"], rtol=1e-5, atol=1e-7)
    # plastic: nonlinear per lane
    pm = [PLASTIC_CASES[1], PLASTIC_CASES[3]]
    ids = np.arange(n) % 2
    p = _params("plastic", n, materials=(pm, ids))
    f = np.array(pl.eval(p, dwi, dwo))
    for k, prm in enumerate(pm):
        sel = ids == k
        np.testing.assert_allclose(f[:, sel], _eval_pdf("plastic", prm, wi[:, sel], wo[:, sel])[0],
                                   rtol=1e-6, atol=1e-9)
    # one kind of material only: trace-time constants, no per-lane choice
    p = _params("roughplastic", 4, distribution="ggx")
    assert p.beckmann is False and p.visible is True


# ================================================================ through the material table
def _scene(specs):
    from pathlib import Path

    from drpt.scene.model import Background, Material, PerspectiveCamera, Planes, Scene, Spheres, Triangles

    cam = PerspectiveCamera((0, 0, 5), (0, 0, -1), (0, 1, 0), 40.0)
    mats = [Material(f"m{i}", bsdf=s) for i, s in enumerate(specs)]
    pos = np.array([[[-1.0, -1, 0], [1, -1, 0], [1, 1, 0]]] * len(specs))
    return Scene(Path("t.txt"), cam, mats, Triangles(pos, np.arange(len(specs), dtype=np.int32),
                                                     uvs=np.zeros((len(specs), 3, 2))),
                 Spheres.empty(), Planes.empty(), [], Background())


UV = (0.3, 0.6)  # drpt's uv of every lane; Mitsuba's bitmap is looked up at (u, 1 - v)


def _interaction(wi, material):
    from drpt.render.surface import Interaction

    n = wi.shape[1]
    z = Array3f(dr.zeros(Float, n), dr.zeros(Float, n), dr.full(Float, 1.0, n))
    uv = Array2f(dr.full(Float, UV[0], n), dr.full(Float, UV[1], n))
    return Interaction(dr.full(Bool, True, n), dr.full(Float, 1.0, n), dr.zeros(Array3f, n), z, z,
                       dr.zeros(UInt32, n), UInt32(np.asarray(material, np.uint32)), to_drpt(wi, Array3f), uv)


@pytest.mark.mitsuba
def test_material_table_renders_plastics_as_mitsuba(tmp_path):
    """Plastic and roughplastic materials (textured reflectances, nonlinear,
    both distributions, sample_visible off, twosided, a blend with a Dirac
    part) and a diffuse one in one real MaterialTable: derive(), the
    uploaded FIELDS (incl. the transmittance table and table_lerp), params()
    with mixed trace-time choices, against Mitsuba's plugins as exported."""
    mi = mitsuba()
    from PIL import Image

    from drpt.export.mitsuba_bsdf import to_mitsuba
    from drpt.materials.spec import BSDFSpec, Texture, complete
    from drpt.render.material import MaterialTable

    img = np.random.default_rng(30).integers(0, 256, (4, 5, 3), dtype=np.uint8)
    Image.fromarray(img).save(tmp_path / "t.png")
    tex = Texture(tmp_path / "t.png", 0.5)
    leaves = [BSDFSpec("plastic"),
              BSDFSpec("plastic", {"diffuse_reflectance": tex, "specular_reflectance": TINT, "nonlinear": True,
                                   "int_ior": "bk7"}),
              BSDFSpec("twosided", {}, [BSDFSpec("roughplastic", {"distribution": "ggx", "alpha": 0.3,
                                                                  "nonlinear": True,
                                                                  "diffuse_reflectance": COLOR})]),
              BSDFSpec("roughplastic", {"alpha": 0.1, "sample_visible": False, "int_ior": 1.7, "ext_ior": 1.0}),
              BSDFSpec("roughplastic", {"distribution": "ggx", "alpha": 0.05, "specular_reflectance": tex}),
              BSDFSpec("blendbsdf", {"weight": 0.3}, [BSDFSpec("plastic", {"diffuse_reflectance": COLOR}),
                                                      BSDFSpec("roughplastic", {"alpha": 0.2})]),
              BSDFSpec("diffuse", {"kd": (0.3, 0.4, 0.5)})]
    specs = [complete(s) for s in leaves]
    table = MaterialTable(_scene(specs))
    assert table.lobes["plastic"] is pl and table.lobes["roughplastic"] is rp
    n = 4000
    for m, spec in enumerate(specs):
        wi, wo = _pairs(n, 40 + m)
        f, pdf = table.eval_pdf(_interaction(wi, np.full(n, m)), to_drpt(wo, Array3f))
        f, pdf = np.array(f), np.array(pdf)
        ref = mi.load_dict(to_mitsuba(spec))
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        si.wi = to_mitsuba_vec3(wi)
        si.uv = mi.Point2f(UV[0], 1.0 - UV[1])
        si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
        ctx = mi.BSDFContext()
        fm, pm = np.array(ref.eval(ctx, si, to_mitsuba_vec3(wo))), np.array(ref.pdf(ctx, si, to_mitsuba_vec3(wo)))
        _close(f, fm, rtol=2e-4, atol=1e-6)
        # pdfs where Mitsuba's roughplastic masks its pdf (same side; the front for one-sided ones)
        same = wi[2] * wo[2] > 0 if spec.kind == "twosided" else (wi[2] > 0) & (wo[2] > 0)
        _close(pdf[same], pm[same], rtol=2e-4, atol=1e-6)
        assert np.all(pdf[~same] == 0) and np.count_nonzero(f[0]) > n // 10, m
    # sampling through the table: finite; a smooth sample weighs f / pdf of the mixture;
    # plastic's Dirac samples are flagged and keep their own weight F k_s / P_s
    mat = np.arange(len(specs) * 2000) // 2000
    wi = np.repeat(_dir(40.0)[:, None], mat.size, axis=1).astype(np.float32)
    wi[2, ::2] *= -1  # half from behind
    u = np.random.default_rng(31).random((3, mat.size)).astype(np.float32)
    si = _interaction(wi, mat)
    wo, bs = table.sample(si, Float(u[0]), Array2f(Float(u[1]), Float(u[2])))
    f, pdf = table.eval_pdf(si, wo)
    w, valid, delta = np.array(bs.weight), np.array(bs.valid), np.array(bs.delta)
    assert np.all(np.isfinite(w)) and np.all(w >= 0)
    assert delta[np.isin(mat, [0, 1, 5])].any() and not delta[np.isin(mat, [2, 3, 4, 6])].any()
    back = (wi[2] < 0) & (mat != 2)  # one-sided: nothing from behind
    assert not valid[back].any()
    ok = valid & ~delta & (np.array(pdf) > 0)
    assert ok.sum() > 4000
    np.testing.assert_allclose(w[:, ok], np.array(f)[:, ok] / np.array(pdf)[ok], rtol=1e-4)


# ================================================================ renders
@pytest.mark.mitsuba
@pytest.mark.slow
@pytest.mark.parametrize("spec", [
    {"kind": "plastic", "params": {"diffuse_reflectance": COLOR, "nonlinear": True}},
    {"kind": "roughplastic", "params": {"distribution": "ggx", "alpha": 0.2, "diffuse_reflectance": COLOR,
                                        "int_ior": "bk7"}},
    {"kind": "roughplastic", "params": {"alpha": 0.05, "diffuse_reflectance": (0.2, 0.5, 0.8),
                                        "sample_visible": False}},
], ids=["plastic", "roughplastic-ggx", "roughplastic-beckmann-all"])
def test_render_matches_mitsuba(tmp_path, spec):
    """A sphere of the material in the test box (support.materials, as in tests/validation/test_materials_render.py),
    rendered by drpt and by Mitsuba through the exporter: block z-scores < 4.5."""
    from drpt.materials.spec import BSDFSpec
    from drpt.testing import assert_agree, render_both
    from support.materials import make, with_bsdf

    scene = with_bsdf(make(tmp_path, "phong"), "phong", BSDFSpec(spec["kind"], dict(spec["params"])))
    r, ref, ref_var = render_both(scene, 48, 32, 128, max_depth=6, bsdf="auto")
    assert r.image.mean() > 0.02
    assert_agree(r, ref, ref_var)
