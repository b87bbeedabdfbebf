"""Environment light (drpt/render/lights/envmap.py) and its Mitsuba export.

Statistical checks use z = (estimate - truth) / (standard error of the
mean) and require |z| < 5 (two-sided false alarm ~6e-7 per check, fixed
seeds). Sampling is checked with Mitsuba's chi-square test (drpt/testing.py).
"""

import math
import warnings

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array2f, Array3f, Float

from drpt.export.mitsuba import look_at_matrix
from drpt.export.mitsuba_envmap import to_mitsuba
from drpt.imageio import write_image
from drpt.render.camera import RayCamera
from drpt.render.lights.envmap import LUMINANCE, EnvironmentLight, check_radius, compensation_offset
from drpt.scene import model
from drpt.testing import mitsuba
from drpt.testing import run_chi2 as chi2_on_sphere

Z_MAX = 5.0


# ----------------------------------------------------------------- helpers
def run_chi2(sample, pdf, ires=16, res=61, sample_count=400_000, seed=0):
    """drpt.testing.run_chi2 with a finer pdf quadrature: the envmap pdf is
    piecewise constant with jumps at cell edges (up to 1e5x for the sun),
    which Mitsuba's default 4x4-point trapezoid rule per histogram bin
    misintegrates (PDF sum 0.9957 for the sun map, chi2 ~1e6); 16x16 points
    integrate it to ~1e-4."""
    return chi2_on_sphere(sample, pdf, sample_count=sample_count, res=res, seed=seed, ires=ires)


def uniform(n, seed):
    rng = np.random.default_rng(seed)
    a = rng.random((2, n), dtype=np.float32)
    return Array2f(Float(a[0]), Float(a[1]))


def sphere_dirs(n, seed):
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(3, n))
    d /= np.linalg.norm(d, axis=0)
    return d.astype(np.float32)


def to_a3(d):
    return Array3f(*(Float(np.ascontiguousarray(x)) for x in d))


def analytic_integral(img):
    """Exact integral over the sphere of drpt's bilinear field (per channel).

    Integrated over u, the periodic linear interpolation between column
    centers gives each row's mean; in v the row means are interpolated
    linearly between theta_j = j pi / (H - 1), so each band contributes
    int (m_j + (m_{j+1} - m_j)(theta - theta_j) / h) sin(theta) d theta.
    """
    img = np.asarray(img, np.float64)
    m = img.mean(axis=1)  # (H, 3)
    H = m.shape[0]
    if H == 1:
        return 4 * math.pi * m[0]
    h = math.pi / (H - 1)
    t = np.arange(H) * h
    c, s = np.cos(t), np.sin(t)
    a = (c[:-1] - c[1:])[:, None]
    b = (-h * c[1:] + s[1:] - s[:-1])[:, None] / h
    return 2 * math.pi * (m[:-1] * a + (m[1:] - m[:-1]) * b).sum(axis=0)


def mc_estimate(light, f, n, seed):
    """Mean and standard error of f(d, le) / pdf over light samples."""
    d, le, pdf = light.sample(uniform(n, seed))
    d, le, pdf = np.array(d), np.array(le), np.array(pdf, np.float64)
    assert np.all(np.isfinite(pdf)) and np.count_nonzero(pdf <= 0) <= 2
    ok = pdf > 0  # pdf-0 samples are skipped (their radiance is 0)
    x = np.where(ok, f(d.astype(np.float64), le.astype(np.float64)) / np.where(ok, pdf, 1), 0)
    return x.mean(axis=-1), x.std(axis=-1, ddof=1) / math.sqrt(n)


def gradient_map(H=16, W=32):
    j, i = np.mgrid[0:H, 0:W]
    img = np.stack([1 + 0.5 * np.sin(2 * np.pi * i / W), 0.2 + j / H,
                    0.5 + 0.4 * np.cos(2 * np.pi * (i + j) / W)], -1)
    return img.astype(np.float32)


def sun_map(H=32, W=64, at=(9, 40)):
    img = np.full((H, W, 3), 0.5, np.float32)
    img[at] = 0.5e5  # 1e5 x the sky
    return img


def black_half_map(H=16, W=32):
    img = gradient_map(H, W)
    img[:, W // 2:] = 0.0  # right half black (incl. the wrap neighbors)
    img[: H // 4] = 0.0  # and the top quarter
    return img


def bright_poles_map(H=64, W=16):
    img = np.full((H, W, 3), 0.01, np.float32)
    img[0] = (50.0, 40.0, 30.0)  # row 0 is the north pole itself
    img[-1, 3] = 500.0  # one texel of the south pole row
    return img


MAPS = {
    "gradient": gradient_map,
    "sun": sun_map,
    "one_texel": lambda: np.full((1, 1, 3), 2.0, np.float32),
    "black_half": black_half_map,
    "bright_poles": bright_poles_map,
    "tiny_2x2": lambda: np.array([[[1, 2, 3], [4, 0, 1]], [[0, 0, 0], [5, 1, 1]]], np.float32),
}


# ------------------------------------------------------------ sampling
@pytest.mark.mitsuba
@pytest.mark.parametrize("name", [m for m in MAPS if m != "bright_poles"])
def test_chi2_sample_matches_pdf(name):
    # bright_poles is left to the exact test below: its pdf is concentrated
    # in thin wedges at the poles, which even 16x16-point quadrature per
    # histogram bin misintegrates by ~1-2% (PDF sum 0.98-1.04).
    light = EnvironmentLight(MAPS[name]())
    ok, msg = run_chi2(lambda u: light.sample(u)[0], light.pdf)
    assert ok, msg


def _linear_cdf(a, b, x):
    """CDF on [0, 1] of the density proportional to lerp(a, b, x)."""
    tot = 0.5 * (a + b)
    return np.where(tot > 0, (a * x + 0.5 * (b - a) * x * x) / np.where(tot > 0, tot, 1), x)


@pytest.mark.slow
@pytest.mark.parametrize("name", list(MAPS))
def test_cells_sampled_with_table_probabilities(name):
    """Quadrature-free check of the scheme: cell counts against P(cell) =
    cell density * solid angle (Pearson chi2, cells with >= 5 expected), and
    inside the cells the exact bilinear density of the corner luminances:
    its marginal CDF in ft (fraction of the band's cos theta range) and the
    conditional CDF in fx, evaluated at the samples, are uniform (KS)."""
    from scipy import stats

    img = MAPS[name]()
    light = EnvironmentLight(img)
    H, W = img.shape[:2]
    ny = max(H - 1, 1)
    n = 1_000_000
    d = np.array(light.sample(uniform(n, 21))[0], np.float64)
    u = np.arctan2(d[0], -d[2]) / (2 * np.pi)
    x = u - 0.5 / W
    x = (x - np.floor(x)) * W
    y = np.arccos(np.clip(d[1], -1, 1)) / np.pi * ny
    ix, iy = np.minimum(x.astype(int), W - 1), np.minimum(y.astype(int), ny - 1)
    cos_edges = np.cos(np.arange(ny + 1) * np.pi / ny)
    omega = (2 * np.pi / W) * (cos_edges[:-1] - cos_edges[1:])
    prob = (np.array(light._pdf, np.float64).reshape(ny, W) * omega[:, None]).ravel()
    assert abs(prob.sum() - 1) < 1e-5
    count = np.bincount(iy * W + ix, minlength=ny * W)
    assert count[prob == 0].sum() <= 2  # edge round-off only
    e = prob * n
    m = e >= 5
    if m.sum() > 1:
        chi = ((count[m] - e[m]) ** 2 / e[m]).sum()
        assert stats.chi2.sf(chi, m.sum() - 1) > 1e-3, chi
    lum = img.astype(np.float64) @ LUMINANCE
    r1 = np.minimum(iy + 1, H - 1)
    c00, c10 = lum[iy, ix], lum[iy, (ix + 1) % W]
    c01, c11 = lum[r1, ix], lum[r1, (ix + 1) % W]
    ft = np.clip((cos_edges[iy] - d[1]) / (cos_edges[iy] - cos_edges[iy + 1]), 0, 1)
    fx = x - ix
    u_t = _linear_cdf(c00 + c10, c01 + c11, ft)
    u_x = _linear_cdf(c00 + (c01 - c00) * ft, c10 + (c11 - c10) * ft, fx)
    assert stats.kstest(u_t, "uniform").pvalue > 1e-3
    assert stats.kstest(u_x, "uniform").pvalue > 1e-3


def test_light_sampling_weight_follows_the_radiance():
    """Inside a cell the density follows the bilinear radiance, so the
    luminance of eval / pdf is nearly constant. On the sun map its relative
    variance is 2.6e-4; the previous piecewise-constant density (max of the
    corners per cell) had 0.79 (and 0.29 vs Mitsuba's 4e-6 on the showcase
    day sky, now 1e-6). What remains is the difference between ft (linear
    in cos theta) and eval's fy (linear in theta)."""
    light = EnvironmentLight(sun_map())
    _, le, pdf = light.sample(uniform(400_000, 5))
    w = (np.array(le, np.float64).T @ LUMINANCE) / np.array(pdf, np.float64)
    assert w.var() / w.mean() ** 2 < 1e-3


@pytest.mark.parametrize("name", list(MAPS))
def test_sample_returns_eval_and_pdf(name):
    """The sample's radiance and density, from the cell it drew, are eval(d) and pdf(d)
    up to rounding (:func:`sample_disagreement`'s thresholds), never 0 but at a
    black cell's edge."""
    light = EnvironmentLight(MAPS[name]())
    d, le, pdf = light.sample(uniform(200_000, 1))
    dn = np.array(d)
    np.testing.assert_allclose(np.linalg.norm(dn, axis=0), 1.0, atol=1e-6)
    assert sample_disagreement(light, d, le, pdf) <= 2, name
    p = np.array(pdf)
    assert np.all(np.isfinite(p))
    # a sample exactly on the edge of a black cell may read that cell (pdf 0,
    # radiance 0): allowed, but only as round-off
    assert np.count_nonzero(p <= 0) <= (2 if name == "black_half" else 0)
    assert np.all(np.array(le)[:, p <= 0] == 0)


def sample_disagreement(light, d, le, pdf, rtol=1e-2):
    """How many samples' radiance or density (:meth:`EnvironmentLight.sample`, computed
    from the cell drawn) differ from ``eval(d)`` / ``pdf(d)`` (a lookup of ``d``) by more
    than ``rtol`` relative (radiance: of its largest channel). Rounding makes them differ:
    ``d`` maps back to where it was drawn up to the float32 rounding of ``cos theta``, up to
    ~7e-3 relative within a few texels of a pole (``1 - cos theta`` near 0), ~1e-6 elsewhere; a
    sample on a cell's edge may read the neighbour's density (a handful in 1e5)."""
    le, pdf = np.array(le, np.float64), np.array(pdf, np.float64)
    le2, pdf2 = np.array(light.eval(d), np.float64), np.array(light.pdf(d), np.float64)
    bad_pdf = np.abs(pdf - pdf2) > rtol * np.maximum(pdf, pdf2)
    scale = np.maximum(np.abs(le).max(0), np.abs(le2).max(0))
    bad_le = (np.abs(le - le2) > rtol * scale).any(0)
    return int(np.count_nonzero(bad_pdf | bad_le))


def test_negative_control_sample_with_theta_fraction_as_cos_fraction_disagrees(monkeypatch):
    """Negative control of :func:`sample_disagreement`: a sample whose radiance reads the
    band at its ``cos theta`` fraction instead of eval's ``theta`` one (the two row
    parameterisations confused) is caught on a map of one wide band."""
    light = EnvironmentLight(MAPS["tiny_2x2"]())
    d, le, pdf = light.sample(uniform(20_000, 1))
    assert sample_disagreement(light, d, le, pdf) <= 2
    monkeypatch.setattr(EnvironmentLight, "_row_fraction",
                        lambda self, cos_t, row: dr.clip(0.5 - 0.5 * cos_t - Float(row), 0.0, 1.0))
    d, le, pdf = light.sample(uniform(20_000, 1))
    assert sample_disagreement(light, d, le, pdf) > 1000


@pytest.mark.parametrize("name", list(MAPS))
def test_pdf_positive_wherever_eval_positive(name):
    light = EnvironmentLight(MAPS[name]())
    d = sphere_dirs(200_000, 2)
    # add the poles and the u = 0 seam
    extra = np.array([[0, 0, 0, 0.6, -1e-7], [1, -1, 1, 0, 0.8], [0, 0, -1e-7, -0.8, -0.6]],
                     np.float32)
    d = np.concatenate([d, extra / np.linalg.norm(extra, axis=0)], axis=1)
    le, pdf = np.array(light.eval(to_a3(d))), np.array(light.pdf(to_a3(d)))
    assert np.all(np.isfinite(pdf)) and np.all(np.isfinite(le))
    assert np.all(pdf[le.max(axis=0) > 0] > 0)


@pytest.mark.parametrize("name", list(MAPS))
def test_integral_matches_analytic(name):
    img = MAPS[name]()
    light = EnvironmentLight(img, scale=1.5)
    mean, se = mc_estimate(light, lambda d, le: le, 400_000, 3)
    truth = 1.5 * analytic_integral(img)
    z = (mean - truth) / np.maximum(se, 2e-6 * np.abs(truth))  # float32 floor
    assert np.all(np.abs(z) < Z_MAX), (mean, truth, z)


def test_constant_map_integral_is_4pi_L():
    light = EnvironmentLight(np.full((8, 16, 3), 0.7, np.float32))
    mean, se = mc_estimate(light, lambda d, le: le, 200_000, 4)
    # piecewise constant pdf on a constant map: zero variance up to rounding
    np.testing.assert_allclose(mean, 4 * math.pi * 0.7, rtol=1e-4)


@pytest.mark.parametrize("normal", [(0, 1, 0), (0.3, -0.5, 0.81)])
def test_furnace_cosine_irradiance_is_pi(normal):
    """White constant sky (L = 1): E[L cos+ / pdf] = pi (albedo-1 diffuse -> 1)."""
    light = EnvironmentLight(np.ones((16, 32, 3), np.float32))
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    mean, se = mc_estimate(light, lambda d, le: le * np.maximum(n @ d, 0.0), 400_000, 5)
    z = (mean - math.pi) / se
    assert np.all(np.abs(z) < Z_MAX), (mean, z)


# ------------------------------------------------------------ Mitsuba
def mitsuba_envmap(tmp_path, img, name="sky.exr", scale=1.0):
    mi = mitsuba()
    p = tmp_path / name
    write_image(p, img)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        desc = to_mitsuba(model.Skybox(p), scale=scale, out_dir=tmp_path / "fixed")
    desc = dict(desc, to_world=mi.ScalarTransform4f(desc["to_world"]))
    return p, desc


def mitsuba_eval(emitter_desc, d):
    mi = mitsuba()
    e = mi.load_dict(emitter_desc)
    si = dr.zeros(mi.SurfaceInteraction3f, d.shape[1])
    si.wi = mi.Vector3f(-d)
    return np.array(e.eval(si))


@pytest.mark.mitsuba
@pytest.mark.parametrize("name", ["gradient", "sun", "one_texel", "tiny_2x2", "bright_poles"])
def test_eval_equals_mitsuba_envmap(tmp_path, name):
    img = MAPS[name]()
    _, desc = mitsuba_envmap(tmp_path, img, scale=0.5)
    d = sphere_dirs(50_000, 6)
    ref = mitsuba_eval(desc, d)
    got = np.array(EnvironmentLight(img, scale=0.5).eval(to_a3(d)))
    # float32 transcendental rounding (acos near the poles) only
    np.testing.assert_allclose(got, ref, rtol=2e-5, atol=2e-5 * float(ref.max()))


def render_both(tmp_path, img, cam, W=64, H=48, spp=256):
    mi = mitsuba()
    _, env = mitsuba_envmap(tmp_path, img)
    c = np.asarray(cam.center, float)
    f = np.asarray(cam.direction, float)
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 1, "hide_emitters": False},
        "sensor": {"type": "perspective", "fov_axis": "y", "fov": cam.fov,
                   "to_world": mi.ScalarTransform4f(look_at_matrix(c, c + f, cam.up)),
                   "film": {"type": "hdrfilm", "width": W, "height": H, "pixel_format": "rgb",
                            "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": spp}},
        "env": env,
    })
    ref = np.array(mi.render(scene, spp=spp, seed=3), np.float64)
    y, x = np.mgrid[0:H, 0:W].astype(np.float32) + 0.5
    _, d = RayCamera(cam, W, H).ray(Float(x.ravel()), Float(y.ravel()))
    light = EnvironmentLight(img)
    ours = np.array(light.eval(d)).T.reshape(H, W, 3)
    dn = np.array(d)
    mirrored = np.array(light.eval(to_a3(dn * np.array([[-1], [1], [1]], np.float32)))).T
    return ref, ours, mirrored.reshape(H, W, 3)


def centroid(a):
    w = a.sum(-1)
    w = np.where(w > 0.5 * w.max(), w, 0.0)
    y, x = np.mgrid[0:a.shape[0], 0:a.shape[1]]
    return np.array([(w * x).sum(), (w * y).sum()]) / w.sum()


def texel_direction(i, j, W, H):
    u, v = (i + 0.5) / W, j / (H - 1)
    p, t = 2 * math.pi * u, math.pi * v
    return np.array([math.sin(p) * math.sin(t), math.cos(t), -math.cos(p) * math.sin(t)])


@pytest.mark.mitsuba
@pytest.mark.parametrize("texel, offset, up", [
    ((3, 5), (0.15, 0.1, 0.0), (0, 1, 0)),  # column 3, row 5
    ((17, 9), (-0.1, 0.0, 0.2), (0.2, 1, 0.1)),
])
def test_marked_texel_appears_where_drpt_says(tmp_path, texel, offset, up):
    Wm, Hm = 24, 12
    img = np.full((Hm, Wm, 3), 0.05, np.float32)
    img[texel[1], texel[0]] = (100.0, 60.0, 30.0)
    # look near (not exactly at) the texel so the spot is off center
    direction = texel_direction(*texel, Wm, Hm) + np.asarray(offset)
    cam = model.PerspectiveCamera(center=(1.0, 2.0, -3.0), direction=tuple(direction), up=up,
                                  fov=70.0)
    ref, ours, mirrored = render_both(tmp_path, img, cam)
    assert ours.max() > 20 and ref.max() > 20  # the spot is in view
    c_ref, c_ours = centroid(ref), centroid(ours)
    assert np.linalg.norm(c_ref - c_ours) < 0.5, (c_ref, c_ours)
    assert np.linalg.norm(c_ref - np.array([32, 24])) > 3  # really off center
    scale = ref.max()
    err = np.abs(ours - ref)
    assert err.max() < 0.06 * scale, err.max() / scale
    # the test can tell: a mirrored u convention is far off
    assert np.abs(mirrored - ref).max() > 0.3 * scale


# ------------------------------------------------------------ extremes
def test_sun_finite_and_mostly_sampled():
    img = sun_map()
    light = EnvironmentLight(img)
    d, le, pdf = light.sample(uniform(100_000, 7))
    le, pdf = np.array(le), np.array(pdf)
    assert np.all(np.isfinite(le)) and np.all(np.isfinite(pdf)) and np.all(pdf > 0)
    # the sun's bilinear footprint holds nearly all the power
    assert np.mean(le.max(0) > 100.0) > 0.9


def test_one_texel_map_is_constant():
    light = EnvironmentLight(np.array([[[0.25, 0.5, 1.0]]], np.float32))
    d = sphere_dirs(1000, 8)
    le = np.array(light.eval(to_a3(d)))
    np.testing.assert_array_equal(le, np.tile([[0.25], [0.5], [1.0]], (1, 1000)).astype(np.float32))
    p = np.array(light.pdf(to_a3(d)))
    assert np.all(np.isfinite(p)) and np.all(p > 0)
    # at the exact poles too (no 1 / sin(theta))
    poles = to_a3(np.array([[0, 0], [1, -1], [0, 0]], np.float32))
    assert np.all(np.isfinite(np.array(light.pdf(poles))))


def test_gray_and_rgba_inputs():
    g = EnvironmentLight(np.full((4, 8, 1), 0.5, np.float32))
    a = EnvironmentLight(np.full((4, 8, 4), 0.5, np.float32))
    d = to_a3(sphere_dirs(100, 9))
    np.testing.assert_allclose(np.array(g.eval(d)), 0.5, rtol=1e-6)
    np.testing.assert_allclose(np.array(a.eval(d)), 0.5, rtol=1e-6)


def test_large_map_builds_and_samples():
    rng = np.random.default_rng(10)
    img = rng.random((2048, 4096, 3), dtype=np.float32)
    img[300:304, 1000:1004] = 1e5
    light = EnvironmentLight(img)
    d, le, pdf = light.sample(uniform(10_000, 11))
    assert sample_disagreement(light, d, le, pdf) <= 2
    le, pdf = np.array(le), np.array(pdf)
    assert np.all(np.isfinite(pdf)) and np.all(pdf > 0) and np.all(np.isfinite(le))


def test_black_map():
    light = EnvironmentLight(np.zeros((8, 16, 3), np.float32))
    assert light.is_black
    d, le, pdf = light.sample(uniform(100, 12))
    assert np.all(np.array(pdf) == 0) and np.all(np.array(le) == 0)
    assert np.all(np.isfinite(np.array(d)))
    dd = to_a3(sphere_dirs(100, 13))
    assert np.all(np.array(light.pdf(dd)) == 0) and np.all(np.array(light.eval(dd)) == 0)
    assert EnvironmentLight(np.ones((2, 2, 3), np.float32), scale=0.0).is_black


def test_nan_inf_negative_texels_are_zeroed_and_reported():
    img = np.ones((4, 8, 3), np.float32)
    img[0, 0, 1] = np.nan
    img[1, 2] = -1.0
    img[2, 3, 0] = np.inf
    img[3, 7, 2] = -np.inf
    light = EnvironmentLight(img, name="environment.hdr")
    assert light.warnings == ["environment.hdr: 4 NaN/Inf/negative texels set to 0"]
    assert not np.isnan(img[0, 0, 0])  # the caller's array is untouched
    d = to_a3(sphere_dirs(20_000, 14))
    le, pdf = np.array(light.eval(d)), np.array(light.pdf(d))
    assert np.all(np.isfinite(le)) and np.all(le >= 0) and np.all(np.isfinite(pdf))
    # the texel at column 2, row 1 (u = 2.5/8, v = 1/3) reads exactly 0
    t = texel_direction(2, 1, 8, 4).astype(np.float32)[:, None]
    np.testing.assert_allclose(np.array(light.eval(to_a3(t))), 0.0, atol=1e-5)
    assert EnvironmentLight(np.ones((4, 8, 3), np.float32)).warnings == []


@pytest.mark.mitsuba
def test_from_file_names_the_file_and_export_fixes_a_copy(tmp_path):
    img = gradient_map(8, 16)
    img[2, 5] = -3.0
    p = tmp_path / "sky.exr"
    write_image(p, img)
    light = EnvironmentLight.from_file(p)
    assert light.warnings == ["sky.exr: 1 NaN/Inf/negative texel set to 0"]
    with pytest.warns(UserWarning, match="NaN/Inf/negative"):
        desc = to_mitsuba(model.Skybox(p), out_dir=tmp_path / "fixed")
    assert desc["filename"] != str(p.resolve())
    mi = mitsuba()
    desc = dict(desc, to_world=mi.ScalarTransform4f(desc["to_world"]))
    d = sphere_dirs(5000, 15)
    np.testing.assert_allclose(np.array(light.eval(to_a3(d))), mitsuba_eval(desc, d),
                               rtol=2e-5, atol=2e-5)


def test_to_mitsuba_plain_file(tmp_path):
    p = tmp_path / "sky.exr"
    write_image(p, gradient_map())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        desc = to_mitsuba(model.Skybox(p, 500.0), scale=2.0)
    assert desc["type"] == "envmap" and desc["filename"] == str(p.resolve())
    assert desc["scale"] == 2.0
    np.testing.assert_array_equal(desc["to_world"], np.eye(4))


def test_check_radius():
    assert check_radius((-1, -1, -1), (1, 2, 1), 1000.0) is None
    msg = check_radius((-10, 0, -10), (800, 700, 10), 1000.0)
    assert msg is not None and "1000" in msg
    # infinite (plane) extents and empty boxes are ignored
    assert check_radius((-np.inf, 0, -1), (np.inf, 1, 1), 1000.0) is None
    assert check_radius((1, 1, 1), (-1, -1, -1), 1.0) is None


def test_sky_warnings_name_the_skybox_line(tmp_path):
    from drpt.errors import Loc
    from drpt.options import RenderOptions
    from drpt.render.scene import DeviceScene
    from drpt.scene import load_scene

    write_image(tmp_path / "sky.exr", gradient_map(8, 16))
    p = tmp_path / "s.txt"
    p.write_text("PerspectiveCamera { center 0 0 5 direction 0 0 -1 up 0 1 0 angle 40 }\n"
                 "Lights { numLights 2\n  Skybox { sky.exr R 1 }\n  Skybox { sky.exr }\n}\n"
                 "Group { numObjects 1\n  Sphere { center 0 0 0 radius 3 }\n}\n")
    scene = load_scene(p)
    assert [sky.loc for sky in scene.lights] == [Loc(p.resolve(), 3), Loc(p.resolve(), 4)]
    warnings_ = DeviceScene(scene, RenderOptions(progress=False)).warnings
    assert f"{p.resolve()}:4: 2 Skybox lights: using the first" in warnings_, warnings_
    assert any(w.startswith(f"{p.resolve()}:3: skybox radius 1: geometry reaches") for w in warnings_), warnings_


# ------------------------------------------------------------ MIS compensation
# (EnvironmentLight.compensated: the density follows max(luminance - mean, 0); it is checked
# against its own sampling, it is 0 exactly where the four texels around a direction are all
# below the mean, and the compensated sample is unbiased only combined by MIS with a technique
# that covers the rest; the negative control, the compensated sample alone, reads |z| > 20)
COMPENSATED = ["gradient", "sun", "black_half", "tiny_2x2"]


def test_offset_is_the_texel_mean_and_off_for_nearly_constant_maps():
    lum = gradient_map() @ LUMINANCE
    assert compensation_offset(lum) == pytest.approx(lum.mean(), rel=1e-12)
    assert compensation_offset(np.full((4, 8), 2.0)) == 0.0
    flat = np.full((4, 8), 1.0)
    flat[0, 0] = 0.995  # minimum within 1% of the mean: Mitsuba's rule leaves it alone
    assert compensation_offset(flat) == 0.0
    flat[0, 0] = 0.5
    assert compensation_offset(flat) > 0.0
    assert compensation_offset(np.zeros((4, 8))) == 0.0
    # a map with nothing to move is its own compensated copy
    one = EnvironmentLight(MAPS["one_texel"]())
    assert one.compensated() is one
    black = EnvironmentLight(np.zeros((4, 8, 3), np.float32))
    assert black.compensated() is black


def test_compensated_copy_shares_the_radiance_and_the_power():
    light = EnvironmentLight(sun_map(), scale=2.0)
    comp = light.compensated()
    assert comp is not light and comp.offset > 0.0 and light.offset == 0.0
    assert comp._data is light._data
    assert comp.luminance_integral == light.luminance_integral
    # the constructor's flag builds the same tables
    again = EnvironmentLight(sun_map(), scale=2.0, compensation=True)
    assert again.offset == comp.offset
    assert np.array_equal(np.array(again._pdf), np.array(comp._pdf))
    d = to_a3(sphere_dirs(20_000, 31))
    assert np.array_equal(np.array(comp.eval(d)), np.array(light.eval(d)))


@pytest.mark.mitsuba
@pytest.mark.parametrize("name", COMPENSATED)
def test_chi2_compensated_sample_matches_pdf(name):
    light = EnvironmentLight(MAPS[name]()).compensated()
    assert light.offset > 0.0
    ok, msg = run_chi2(lambda u: light.sample(u)[0], light.pdf)
    assert ok, msg


@pytest.mark.parametrize("name", COMPENSATED)
def test_compensated_sample_returns_eval_and_pdf(name):
    light = EnvironmentLight(MAPS[name]()).compensated()
    d, le, pdf = light.sample(uniform(100_000, 32))
    assert sample_disagreement(light, d, le, pdf) <= 2, name
    p = np.array(pdf)
    assert np.all(np.isfinite(p)) and np.count_nonzero(p <= 0) <= 2  # edge round-off only


@pytest.mark.parametrize("name", ["gradient", "sun", "black_half"])  # (tiny_2x2: no cell all below)
def test_density_zero_exactly_where_the_corners_are_below_the_mean(name):
    """The density is positive where a corner of the bilinear cell around ``d`` is above the
    mean, and 0 where all four are at or below it; the uncompensated density is positive
    wherever the radiance is."""
    img = MAPS[name]()
    light = EnvironmentLight(img)
    comp = light.compensated()
    H, W = img.shape[:2]
    ny = max(H - 1, 1)
    d = sphere_dirs(100_000, 33).astype(np.float64)
    u = np.arctan2(d[0], -d[2]) / (2 * np.pi)
    x = u - 0.5 / W
    x = (x - np.floor(x)) * W
    y = np.arccos(np.clip(d[1], -1, 1)) / np.pi * ny
    ix, iy = np.minimum(x.astype(int), W - 1), np.minimum(y.astype(int), ny - 1)
    lum = img.astype(np.float64) @ LUMINANCE
    r1 = np.minimum(iy + 1, H - 1)
    corners = np.stack([lum[iy, ix], lum[iy, (ix + 1) % W], lum[r1, ix], lum[r1, (ix + 1) % W]])
    above = (corners > comp.offset * (1 + 1e-6)).any(0)
    below = (corners < comp.offset * (1 - 1e-6)).all(0)
    # away from cell edges (where float32 lookups may pick the neighbour cell)
    inner = (np.abs(x - np.round(x)) > 1e-3) & (np.abs(y - np.round(y)) > 1e-3)
    p = np.array(comp.pdf(to_a3(d.astype(np.float32))))
    assert np.all(p[inner & below] == 0.0)
    assert np.all(p[inner & above] > 0.0)
    assert (inner & below).any() and (inner & above).any()


def _mis_estimate(light, n, seed, mis=True):
    """One-sample-per-technique MIS estimate of the integral of the map's radiance over the
    sphere, from the light's own sampling and uniform sphere sampling (the stand-in for a
    BSDF sample), combined by the balance heuristic; ``mis`` False: the light's sample
    alone (weight 1). Mean and standard error per channel."""
    pu = 1.0 / (4.0 * math.pi)
    d, le, pdf = light.sample(uniform(n, seed))
    le, pl = np.array(le, np.float64), np.array(pdf, np.float64)
    ok = pl > 0
    w = pl / (pl + pu) if mis else np.ones_like(pl)
    x = np.where(ok, le * w / np.where(ok, pl, 1.0), 0.0)
    if mis:
        r = np.random.default_rng(seed + 1)
        z = 1.0 - 2.0 * r.random(n)
        phi = 2.0 * math.pi * r.random(n)
        s = np.sqrt(np.maximum(1.0 - z * z, 0.0))
        du = np.stack([s * np.cos(phi), z, s * np.sin(phi)]).astype(np.float32)
        leu, pl_u = light.eval_pdf(to_a3(du))
        leu, pl_u = np.array(leu, np.float64), np.array(pl_u, np.float64)
        x = x + leu * (pu / (pl_u + pu)) / pu
    return x.mean(-1), x.std(-1, ddof=1) / math.sqrt(n)


@pytest.mark.parametrize("name", ["gradient", "sun", "black_half"])
def test_compensated_sample_is_unbiased_with_its_mis_complement(name):
    img = MAPS[name]()
    light = EnvironmentLight(img, scale=1.5).compensated()
    truth = 1.5 * analytic_integral(img)
    mean, se = _mis_estimate(light, 400_000, 34)
    z = (mean - truth) / np.maximum(se, 2e-6 * np.abs(truth))
    assert np.all(np.abs(z) < Z_MAX), (mean, truth, z)


@pytest.mark.parametrize("name", ["gradient", "sun"])
def test_negative_control_compensated_sample_alone_is_biased(name):
    """Without the complement the directions below the mean are never sampled: the estimate
    misses their share (the gradient's darker half, the sun map's sky). (On ``black_half``
    every cell with radiance has a corner above the mean, so there the sample alone happens
    to cover the whole support.)"""
    img = MAPS[name]()
    light = EnvironmentLight(img, scale=1.5).compensated()
    truth = 1.5 * analytic_integral(img)
    mean, se = _mis_estimate(light, 400_000, 34, mis=False)
    z = (mean - truth) / np.maximum(se, 2e-6 * np.abs(truth))
    assert np.all(np.abs(z) > 20), z
    # the uncompensated light alone is unbiased (the control's baseline)
    mean, se = _mis_estimate(EnvironmentLight(img, scale=1.5), 400_000, 34, mis=False)
    assert np.all(np.abs((mean - truth) / se) < Z_MAX)


def test_black_half_keeps_zero_density_on_black_cells():
    light = EnvironmentLight(black_half_map()).compensated()
    d = sphere_dirs(50_000, 35)
    le, p = np.array(light.eval(to_a3(d))), np.array(light.pdf(to_a3(d)))
    assert np.all(np.isfinite(p)) and np.all(p >= 0)
    assert np.all(p[le.max(0) == 0] == 0)


def test_stored_luminance_is_the_kernels_to_the_bit():
    """Each texel is stored as ``(r, g, b, luminance)`` (one packet gather reads a corner's
    radiance and its sampling weight); the stored luminance is bit for bit what a kernel
    computes from the texel's RGB (negative control: numpy's float64 luminance rounded to
    float32 differs on some texels)."""
    from drpt.render.lights import envmap

    rng = np.random.default_rng(5)
    img = (rng.lognormal(0.0, 2.0, (33, 64, 3))).astype(np.float32)
    light = EnvironmentLight(img)
    stored = light._data.numpy().reshape(33, 64, 4)
    np.testing.assert_array_equal(stored[..., :3], img)
    rgb = img.reshape(-1, 3)
    c = Array3f(Float(rgb[:, 0].copy()) + 0.0 * dr.arange(Float, len(rgb)), Float(rgb[:, 1].copy()),
                Float(rgb[:, 2].copy()))
    kernel = np.array(envmap._luminance(c)).reshape(33, 64)
    np.testing.assert_array_equal(stored[..., 3], kernel)
    assert not np.array_equal((img.astype(np.float64) @ LUMINANCE).astype(np.float32), kernel)


def test_alias_tables_realise_their_probabilities():
    """:func:`alias_tables`: the probabilities it reports are those of its float32 tables and
    are each row's weights to float32 rounding (zero cells and empty rows: 0); picking with
    :func:`_pick` from 2^22 uniforms finds every cell at its probability (|z| < 5 per cell)
    and the remapped number uniform inside each picked cell (its mean and second moment per
    cell, |z| < 5). Negative controls: a pick that ignores the alias
    (each cell kept with its threshold only) misses cells (|z| > 50), and a remap that does
    not rescale on the alias branch leaves the remapped numbers non-uniform (|z| > 50)."""
    from drjit.auto import UInt32

    from drpt.render.lights import envmap

    rng = np.random.default_rng(9)
    w = rng.lognormal(0.0, 2.0, (3, 40))
    w[1, 5:30] = 0.0
    w[2] = 0.0
    q, alias, prob = envmap.alias_tables(w)
    assert q.dtype == np.float32 and alias.dtype == np.uint32
    np.testing.assert_allclose(prob[:2], w[:2] / w[:2].sum(axis=1, keepdims=True), rtol=1e-5, atol=1e-12)
    assert np.all(prob[1, 5:30] == 0.0) and np.all(prob[2] == 0.0)
    realised = q.astype(np.float64)
    for r in range(3):
        np.add.at(realised[r], alias[r].astype(np.int64), 1.0 - q[r].astype(np.float64))
    np.testing.assert_array_equal(np.where(prob > 0, realised / 40, 0.0), prob)

    n = 1 << 22
    u = Float(rng.random(n, dtype=np.float32))
    table = envmap._interleaved(q[0], alias[0])

    def stats(pick):
        cell, s = pick(table, 0, 40, u)
        cell, s = np.array(cell), np.array(s, np.float64)
        counts = np.bincount(cell, minlength=40)
        p = prob[0]
        z_cells = (counts - n * p) / np.sqrt(n * p * (1 - p))
        # uniform in [0, 1) inside each cell: mean 1/2 (variance 1/12), second moment 1/3
        # (variance 4/45)
        seen = np.maximum(counts, 1)
        z_mean = (np.bincount(cell, s, 40) / seen - 0.5) / np.sqrt(1 / 12 / seen)
        z_m2 = (np.bincount(cell, s * s, 40) / seen - 1 / 3) / np.sqrt(4 / 45 / seen)
        return np.abs(z_cells).max(), max(np.abs(z_mean).max(), np.abs(z_m2).max())

    zc, zs = stats(envmap._pick)
    assert zc < Z_MAX and zs < Z_MAX, (zc, zs)

    def no_alias(table_, base, m, u_):
        x = u_ * m
        i = dr.minimum(UInt32(x), m - 1)
        f = x - Float(i)
        return i, f

    def no_rescale(table_, base, m, u_):
        cell, _ = envmap._pick(table_, base, m, u_)
        x = u_ * m
        return cell, x - dr.floor(x)

    assert stats(no_alias)[0] > 50.0
    zs_control = stats(no_rescale)[1]
    assert zs_control > 50.0, zs_control


def _alias_error(w: np.ndarray, q: np.ndarray, alias: np.ndarray) -> float:
    """The largest error of the cell probabilities that the tables ``(q, alias)`` realise
    against the normalised weights ``w``, in units of the float32 rounding that the
    thresholds allow (each cell: one rounding step of its own threshold and of each threshold
    aliasing it, 2^-24 of the row's N picks each), or inf where a zero cell can be picked,
    an index is out of range or an empty row is not left as it is."""
    R, N = w.shape
    if alias.max(initial=0) >= N or not (np.all(q >= 0.0) and np.all(q <= 1.0)):
        return np.inf
    worst = 0.0
    for r in range(R):
        a = alias[r].astype(np.int64)
        qd = q[r].astype(np.float64)
        realised = qd + np.bincount(a, 1.0 - qd, N)  # N times each cell's probability
        if not w[r].sum() > 0.0:
            if not np.array_equal(a, np.arange(N)) or np.any(qd != 1.0):
                return np.inf
            continue
        if np.any(realised[w[r] == 0.0] != 0.0):
            return np.inf
        steps = 1.0 + np.bincount(a, qd < 1.0, N)
        target = w[r] * (N / w[r].sum())
        worst = max(worst, float(np.max(np.abs(realised - target) / (steps * 2.0 ** -23))))
    return worst


@pytest.mark.parametrize("shape", [(6, 9), (1, 13), (7, 1), (40, 50), (3, 4096)])
def test_alias_tables_realise_the_weights(shape):
    """:func:`alias_tables` on random rows (lognormal, 30% zero cells) with a zero row, a row
    with one positive cell, a 1xN and an Nx1 table: every cell's probability realised by
    its threshold and the thresholds aliasing it equals its normalised weight to the float32
    rounding of those thresholds (:func:`_alias_error` at most 1), zero cells are never
    picked, a zero row keeps thresholds 1 aliasing themselves. Negative control: one alias
    pointing one cell off (a cell whose threshold is below 1) fails the comparison."""
    from drpt.render.lights import envmap

    rng = np.random.default_rng(sum(shape))
    w = rng.lognormal(0.0, 1.5, shape)
    w[rng.random(shape) < 0.3] = 0.0
    if shape[0] > 1:
        w[1] = 0.0
    if shape[0] > 2:
        w[2] = 0.0
        w[2, shape[1] // 2] = 3.0
    q, alias, prob = envmap.alias_tables(w)
    assert q.dtype == np.float32 and alias.dtype == np.uint32 and prob.shape == shape
    err = _alias_error(w, q, alias)
    assert err <= 1.0, err
    if shape[0] > 2:
        assert prob[2, shape[1] // 2] == 1.0 and np.count_nonzero(prob[2]) == 1
    if shape[1] > 1:
        r, c = np.argwhere((q < 0.5) & (w > 0.0))[0]  # a cell that mostly hands over to its alias
        bad = alias.copy()
        bad[r, c] = (bad[r, c] + 1) % shape[1]
        control = _alias_error(w, q, bad)
        assert control > 100.0, control


def test_alias_tables_large_skewed_rows():
    """Rows where all the mass sits in one cell, or every cell rounds below 1 (a constant row
    of N = 3: 1/3 * 3 in float64), still realise their weights (:func:`_alias_error`)."""
    from drpt.render.lights import envmap

    w = np.full((4, 3), 1.0 / 3.0)
    w[1] = [1e-300, 1.0, 1e-300]
    w[2] = [0.1, 0.1, 0.1]
    w[3] = [0.0, 0.0, 7.0]
    q, alias, _ = envmap.alias_tables(w)
    assert _alias_error(w, q, alias) <= 1.0
