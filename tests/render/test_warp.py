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
