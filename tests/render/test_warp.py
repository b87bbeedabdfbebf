"""Sample warps and local frames (drpt/render/warp.py)."""

import drjit as dr
import numpy as np
import pytest
from drjit.auto import Array2f, Array3f, Float
from scipy import stats

from drpt.render import warp
from drpt.testing import run_chi2


@pytest.mark.mitsuba
def test_cosine_hemisphere_chi2():
    ok, msg = run_chi2(warp.square_to_cosine_hemisphere,
                       lambda w: warp.cosine_hemisphere_pdf(w.z))
    assert ok, msg


def test_cosine_hemisphere_unit_and_upper():
    rng = np.random.default_rng(1)
    u = rng.random((2, 10000)).astype(np.float32)
    u[:, :4] = [[0, 1, 0.5, 1], [0, 1, 0.5, 0]]  # corners and center
    w = warp.square_to_cosine_hemisphere(Array2f(u))
    w = np.array(w)
    assert np.all(np.isfinite(w))
    assert np.allclose(np.linalg.norm(w, axis=0), 1.0, atol=1e-5)
    assert np.all(w[2] >= 0)


def test_uniform_triangle_is_uniform():
    n, N = 16, 200_000
    rng = np.random.default_rng(2)
    b = np.array(warp.square_to_uniform_triangle(Array2f(rng.random((2, N)).astype(np.float32))))
    assert np.all(b >= 0) and np.all(b.sum(0) <= 1 + 1e-6)
    hist, _, _ = np.histogram2d(b[0], b[1], bins=n, range=[[0, 1], [0, 1]])
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    # Cells below the diagonal hold 2/n^2 of the mass, diagonal cells half that.
    p = np.where(i + j < n - 1, 2.0, np.where(i + j == n - 1, 1.0, 0.0)) / n**2
    keep = p > 0
    assert hist[~keep].sum() == 0
    _, pvalue = stats.chisquare(hist[keep], p[keep] * N)
    assert pvalue > 1e-3  # fixed seed; a correct warp fails this 0.1% of the time


@pytest.mark.parametrize("n", [(0, 0, 1), (0, 0, -1), (1, 0, 0), (0.3, -0.5, 0.81), (1e-8, 0, -1)])
def test_frame_orthonormal_roundtrip(n):
    n = np.array(n, float)
    n /= np.linalg.norm(n)
    f = warp.Frame(Array3f(*map(float, n)))
    s, t, nn = (np.array(v).ravel() for v in (f.s, f.t, f.n))
    basis = np.stack([s, t, nn])
    assert np.allclose(basis @ basis.T, np.eye(3), atol=1e-5)
    v = Array3f(0.2, -0.7, 0.4)
    back = np.array(f.to_world(f.to_local(v))).ravel()
    assert np.allclose(back, [0.2, -0.7, 0.4], atol=1e-6)
    assert np.allclose(np.array(f.to_local(Array3f(*map(float, n)))).ravel(), [0, 0, 1], atol=1e-6)


@pytest.mark.mitsuba
def test_chi2_harness_rejects_a_wrong_pdf():
    # Negative control: the cosine sampler against the uniform-hemisphere pdf.
    ok, _ = run_chi2(warp.square_to_cosine_hemisphere,
                     lambda w: dr.select(w.z > 0, Float(1 / (2 * np.pi)), Float(0)),
                     sample_count=100_000)
    assert not ok


# ------------------------------------------------------------ spherical triangles
#: (corners, reference point, about the solid angle in sr)
SPHERICAL = {
    "near": (((-1.0, -1.0, 1.0), (2.0, -0.5, 0.8), (0.0, 2.0, 1.2)), (0.1, 0.2, 0.0)),  # 1.7 sr
    "grazing": (((-1.0, 0.5, 0.5), (1.5, 0.5, 0.3), (0.0, 0.5, 3.0)), (0.0, 0.0, 0.0)),  # 0.8 sr
    "wide": (((-3.0, -3.0, 0.3), (3.0, -3.0, 0.3), (0.0, 4.0, 0.3)), (0.0, 0.0, 0.0)),  # 5.4 sr
    # the same triangle 0.065 above ref: 6.1 sr, near the hemisphere and under SPHERICAL_MAX
    "hemisphere": (((-3.0, -3.0, 0.065), (3.0, -3.0, 0.065), (0.0, 4.0, 0.065)), (0.0, 0.0, 0.0)),
    "small": (((0.0, 0.0, 10.0), (0.3, 0.0, 10.0), (0.0, 0.3, 10.0)), (0.0, 0.0, 0.0)),  # 4.5e-4 sr
}


def _spherical(corners, ref, n=1):
    p0, p1, p2 = (np.array(c, float) for c in corners)

    def f(v):
        return Array3f(*(Float(np.full(n, x, np.float32)) for x in v))
    return f(p0), f(p1 - p0), f(p2 - p0), f(np.array(ref, float))


def _solid_angle64(corners, ref):
    a, b, c = ((np.array(v, float) - ref) / np.linalg.norm(np.array(v, float) - ref) for v in corners)
    return 2.0 * np.arctan2(abs(a @ np.cross(b, c)), 1.0 + a @ b + b @ c + c @ a)


def _inside(p0, e1, e2, o, w):
    """Whether the ray ``o + t w`` (t > 0) meets the triangle (Moller and Trumbore)."""
    s1 = dr.cross(w, e2)
    inv = dr.rcp(dr.dot(s1, e1))
    sp = o - p0
    b1 = dr.dot(sp, s1) * inv
    s2 = dr.cross(sp, e1)
    b2 = dr.dot(w, s2) * inv
    t = dr.dot(e2, s2) * inv
    return (b1 >= 0) & (b2 >= 0) & (b1 + b2 <= 1) & (t > 0)


@pytest.mark.parametrize("case", list(SPHERICAL))
def test_spherical_triangle_solid_angle(case):
    """The float32 solid angle is float64's to 1e-4 relative, from 4.5e-4 sr to 6.1 sr."""
    corners, ref = SPHERICAL[case]
    t = warp.SphericalTriangle(*_spherical(corners, ref))
    assert float(t.omega[0]) == pytest.approx(_solid_angle64(corners, np.array(ref)), rel=1e-4)
    assert bool(t.sampled[0])


@pytest.mark.mitsuba
@pytest.mark.parametrize("case", ["near", "grazing", "wide", "hemisphere"])  # ("small" is finer than the bins)
def test_spherical_triangle_chi2(case):
    """:func:`warp.spherical_triangle_sample` against the density ``1 / omega`` inside the
    spherical triangle, 0 outside (the bins at its edges integrated at 32 x 32 points). The
    direction is the light's: toward the point of the triangle at
    :func:`warp.ray_triangle_barycentrics` (about 2e-5 of the float32 samples with ``u.x``
    below 1e-3 leave the triangle across the edge ``ab`` by rounding; clamped onto it)."""
    corners, ref = SPHERICAL[case]

    def sample(u):
        p0, e1, e2, o = _spherical(corners, ref, dr.width(u))
        w = warp.spherical_triangle_sample(warp.SphericalTriangle(p0, e1, e2, o), u)
        b = warp.ray_triangle_barycentrics(o, w, p0, e1, e2)
        return dr.normalize(p0 + e1 * b.x + e2 * b.y - o)

    def pdf(w):
        p0, e1, e2, o = _spherical(corners, ref, dr.width(w))
        t = warp.SphericalTriangle(p0, e1, e2, o)
        return dr.select(_inside(p0, e1, e2, o, w), 1.0 / t.omega, 0.0)

    ok, msg = run_chi2(sample, pdf, sample_count=300_000, ires=32)
    assert ok, msg


@pytest.mark.mitsuba
@pytest.mark.parametrize("case", ["near", "hemisphere"])
def test_area_sample_fails_the_solid_angle_chi2(case):
    """Negative control: directions toward points uniform on the triangle (area sampling)
    against the density ``1 / omega`` fail the same test, near the hemisphere too."""
    corners, ref = SPHERICAL[case]

    def sample(u):
        p0, e1, e2, o = _spherical(corners, ref, dr.width(u))
        b = warp.square_to_uniform_triangle(u)
        return dr.normalize(p0 + e1 * b.x + e2 * b.y - o)

    def pdf(w):
        p0, e1, e2, o = _spherical(corners, ref, dr.width(w))
        return dr.select(_inside(p0, e1, e2, o, w), 1.0 / warp.SphericalTriangle(p0, e1, e2, o).omega, 0.0)

    ok, _ = run_chi2(sample, pdf, sample_count=300_000, ires=32)
    assert not ok


#: float32's unit roundoff
EPS32 = float(np.finfo(np.float32).eps) / 2


def test_spherical_triangle_sample_meets_the_triangle():
    """Every sampled direction meets the triangle where its barycentrics say, from the five
    cases' reference points. The point ``p0 + e1 b1 + e2 b2 - ref`` is float32 arithmetic on
    coordinates as large as the farthest corner's distance ``R`` from ``ref``, so its
    component across the direction is rounding of that size, not a fraction of the edge or
    of the point's own distance: at most 4.8 ``EPS32 R`` measured with these 20000 samples a
    case, 6.4 with 200000 (both in "hemisphere"). The bound, 64 ``EPS32 R`` (3.8e-6 R), is
    ten times that. Negative control: a warp off by 1e-3 in ``u`` reads 600 ``EPS32 R`` and
    more in every case (:func:`test_meets_the_triangle_rejects_a_shifted_warp`)."""
    for across in _across(warp.spherical_triangle_sample):
        assert across < 64.0, across


def _across(sampler, n=20_000):
    """Per case, the largest component across the sampled direction of the point its
    barycentrics name, in units of ``EPS32`` times the farthest corner's distance; and the
    barycentrics' range checked."""
    rng = np.random.default_rng(3)
    out = []
    for corners, ref in SPHERICAL.values():
        p0, e1, e2, o = _spherical(corners, ref, n)
        u = Array2f(rng.random((2, n)).astype(np.float32))
        w = sampler(warp.SphericalTriangle(p0, e1, e2, o), u)
        b = warp.ray_triangle_barycentrics(o, w, p0, e1, e2)
        p = np.array(p0 + e1 * b.x + e2 * b.y - o)
        w = np.array(w)
        across = p - w * (p * w).sum(0)
        far = max(np.linalg.norm(np.array(c) - ref) for c in corners)
        out.append(np.abs(across).max() / (EPS32 * far))
        assert (np.array(b.x) >= 0).all() and (np.array(b.y) >= 0).all()
        assert (np.array(b.x + b.y) <= 1 + 1e-6).all()
    return out


def test_meets_the_triangle_rejects_a_shifted_warp():
    """Negative control of the bound above: a warp off by 1e-3 in ``u`` sends directions
    past the triangle's edges, where the clamped barycentrics name a point off the ray."""
    def shifted(t, u):
        return warp.spherical_triangle_sample(t, Array2f(u.x * 1.001 + 1e-3, u.y * 1.001 + 1e-3))

    assert min(_across(shifted)) > 64.0
