"""Statistical checks for drpt's samplers, BSDFs and renders, for the test suite and for
users checking a BSDF or a scene of their own.

Four checks, each with a fixed seed (a pass or fail is reproducible) and a stated threshold:

* :func:`run_chi2` / :func:`spherical_chi2` / :func:`bsdf_chi2`: Mitsuba 3's chi-square
  test on the sphere: does a sampler produce directions with the density its ``pdf`` claims?
* :func:`furnace`: a BSDF's albedo under uniform illumination (the mean sample weight) is
  at most 1, and equal to 1 for a lossless one.
* :func:`block_z` (with :func:`render_both`, :func:`mitsuba_runs`, :func:`assert_agree`,
  :func:`block_z_correlated`): a drpt render against Mitsuba's, per pixel block.
* :func:`z_test`: Mitsuba's own render-test statistic against a reference image and its
  per-sample variance.

Mitsuba 3 (``mitsuba``, a test dependency) is imported only by the functions that need it;
``import drpt.testing`` itself loads neither Mitsuba nor the renderer. See
``docs/validation.md`` for what each statistic means and how the tests use it.
"""

from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass

import numpy as np

from drpt.backend import mitsuba_variant
from drpt.export.mitsuba import to_mitsuba_dict
from drpt.export.mitsuba_bsdf import to_mitsuba
from drpt.materials.spec import BSDFSpec, complete
from drpt.options import PathOptions, RenderOptions
from drpt.render.renderer import Renderer

__all__ = [
    "BATCHES", "SRGB_TO_XYZ", "Furnace", "ZTest", "assert_agree", "block_z", "block_z_correlated",
    "bsdf_chi2", "export_bsdf", "furnace", "mitsuba", "mitsuba_runs", "render_both", "run_chi2",
    "spherical_chi2", "to_drpt", "to_mitsuba_float", "to_mitsuba_vec3", "to_xyz", "z_test",
]


# ------------------------------------------------------------------ Mitsuba adapters
def mitsuba():
    """The ``mitsuba`` module with the variant matching drpt's backend
    (:func:`drpt.backend.mitsuba_variant`) set."""
    import mitsuba as mi

    mi.set_variant(mitsuba_variant())
    return mi


def to_drpt(v, cls):
    """A Mitsuba (or numpy) array ``v`` as the drpt (``drjit.auto``) type ``cls``: ``Float``
    from a 1-D array, ``Array2f``/``Array3f`` from a ``(k, n)`` one."""
    from drjit.auto import Float

    a = np.array(v, dtype=np.float32)
    if a.ndim == 1:
        return cls(Float(a)) if cls is not Float else Float(a)
    return cls(*(Float(np.ascontiguousarray(a[i])) for i in range(a.shape[0])))


def to_mitsuba_vec3(v):
    """A ``(3, n)`` array (or drpt ``Array3f``) as Mitsuba's ``Vector3f``."""
    mi = mitsuba()
    a = np.array(v, dtype=np.float32)
    return mi.Vector3f(a[0], a[1], a[2])


def to_mitsuba_float(x):
    """A 1-D array (or drpt ``Float``) as Mitsuba's ``Float``."""
    mi = mitsuba()
    return mi.Float(np.array(x, dtype=np.float32))


def export_bsdf(kind, two_sided=False, **params):
    """drpt's Mitsuba dict (:func:`drpt.export.mitsuba_bsdf.to_mitsuba`) of a ``kind`` spec
    with ``params`` (defaults filled in), wrapped in ``twosided`` if asked; for
    ``mi.load_dict``."""
    spec = BSDFSpec(kind, params)
    if two_sided:
        spec = BSDFSpec("twosided", children=[spec])
    return to_mitsuba(complete(spec))


# ------------------------------------------------------------------ chi-square on the sphere
def spherical_chi2(sample_func, pdf_func, **kwargs):
    """Mitsuba's ``mitsuba.chi2.ChiSquareTest`` on the sphere.

    ``sample_func(u) -> mi.Vector3f`` and ``pdf_func(w: mi.Vector3f) -> mi.Float`` take and
    return *Mitsuba* types; ``kwargs`` are the test's other arguments (``sample_dim``,
    ``sample_count``, ``res``, ``ires``, ``seed``). The test bins the samples on a
    ``res x 2 res`` grid over (cos theta, phi), integrates the pdf over each bin and rejects
    at significance 1% after a Sidak correction for the number of tests it runs; bins with
    an expected count under 5 are pooled. It runs in a temporary directory (on failure
    Mitsuba writes ``chi2_data.py`` into the working directory).

    Returns ``(passed, messages)``.

    >>> ok, msg = spherical_chi2(sample_func, pdf_func, sample_dim=2)  # doctest: +SKIP
    """
    mitsuba()
    from mitsuba.chi2 import ChiSquareTest, SphericalDomain

    test = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func, **kwargs)
    cwd = os.getcwd()
    with tempfile.TemporaryDirectory() as tmp:
        os.chdir(tmp)
        try:
            ok = test.run()
        finally:
            os.chdir(cwd)
    return ok, test.messages


def run_chi2(sample, pdf, sample_dim=2, sample_count=400_000, res=61, seed=0, ires=None):
    """Chi-square test (:func:`spherical_chi2`) of a drpt direction sampler on the sphere.

    ``sample(u: drjit.auto Array2f) -> drjit.auto Array3f`` (unit directions) and
    ``pdf(w: drjit.auto Array3f) -> drjit.auto Float`` (solid-angle density). Defaults:
    400,000 samples, 61 x 122 bins, seed 0. ``ires``: the points per bin side at which the
    pdf is integrated (None: Mitsuba's default, 4; a density with a sharp edge inside bins
    needs more). Rejects at significance 1% (Sidak-corrected). Returns ``(passed, message)``.

    >>> from drjit.auto import Array3f, Float
    >>> from drpt.render.bsdf import diffuse
    >>> p, wi = diffuse.DiffuseParams(Array3f(0.5)), Array3f(0, 0, 1)
    >>> ok, msg = run_chi2(lambda u: diffuse.sample(p, wi, Float(0.5), u).wo,
    ...                    lambda w: diffuse.pdf(p, wi, w))  # doctest: +SKIP
    """
    mitsuba()
    from drjit.auto import Array2f, Array3f

    def sample_func(u):
        return to_mitsuba_vec3(sample(to_drpt(u, Array2f)))

    def pdf_func(w):
        return to_mitsuba_float(pdf(to_drpt(w, Array3f)))

    extra = {} if ires is None else {"ires": ires}
    return spherical_chi2(sample_func, pdf_func, sample_dim=sample_dim, sample_count=sample_count,
                          res=res, seed=seed, **extra)


def bsdf_chi2(lobe, p, wi, sample_count=400_000, res=61, seed=0, ires=None):
    """Chi-square test (:func:`spherical_chi2`) of a non-delta BSDF lobe's ``sample``
    against its ``pdf`` for one incident direction.

    ``lobe``: a module with the lobe interface of :mod:`drpt.render.bsdf` (``sample(p, wi,
    u1, u2)``, ``pdf(p, wi, wo)``); ``p``: its parameter record (width 1, broadcast);
    ``wi``: a unit local direction, ``(x, y, z)`` or an ``Array3f``. The three sample
    dimensions are ``u1`` (lobe choice) and ``u2``; invalid samples are moved to the pole
    below (``-z``) where the pdf of a reflective lobe is 0, so a lobe that drops valid
    directions fails. Same threshold and return value as :func:`run_chi2`.

    >>> from drjit.auto import Array3f
    >>> from drpt.render.bsdf import diffuse
    >>> ok, msg = bsdf_chi2(diffuse, diffuse.DiffuseParams(Array3f(0.5)), (0.3, 0, 0.954))  # doctest: +SKIP
    """
    mitsuba()
    import drjit as dr
    from drjit.auto import Array2f, Array3f, Float

    w_in = Array3f(*(float(np.asarray(c).ravel()[0]) for c in wi))

    def sample_func(u):
        a = np.array(u, dtype=np.float32)
        bs = lobe.sample(p, w_in, Float(a[0]), Array2f(Float(a[1]), Float(a[2])))
        wo = dr.select(bs.valid & (bs.pdf > 0.0), bs.wo, Array3f(0.0, 0.0, -1.0))
        return to_mitsuba_vec3(wo)

    def pdf_func(w):
        return to_mitsuba_float(lobe.pdf(p, w_in, to_drpt(w, Array3f)))

    extra = {} if ires is None else {"ires": ires}
    return spherical_chi2(sample_func, pdf_func, sample_dim=3, sample_count=sample_count,
                          res=res, seed=seed, **extra)


# ------------------------------------------------------------------ white furnace
@dataclass
class Furnace:
    """The result of :func:`furnace`: per incident direction (rows) and channel (columns),
    the albedo estimate and its standard error; ``passed`` and a readable ``message``."""

    albedo: np.ndarray  # (directions, 3)
    stderr: np.ndarray  # (directions, 3)
    passed: bool
    message: str

    def __str__(self) -> str:
        return self.message


def furnace(sample, wis, n=200_000, seed=0, lossless=False, k=5.0, atol=1e-4) -> Furnace:
    """White-furnace check: the albedo ``a(wi) = integral of f(wi, wo) |cos wo| dwo`` of a
    BSDF, estimated as the mean sample weight (``weight = f |cos| / pdf``), is at most 1 for
    every incident direction and channel, and equal to 1 for a lossless BSDF.

    ``sample(wi: Array3f, u1: Float, u2: Array2f) -> BSDFSample`` (or the weight, an
    ``Array3f``), e.g. ``lambda wi, u1, u2: lobe.sample(p, wi, u1, u2)``; ``wis``: unit
    local directions ``(x, y, z)``. ``n`` uniform samples per direction from
    ``numpy.random.default_rng(seed)``. Threshold: with ``s`` the standard error of the
    mean, each channel passes when ``albedo <= 1 + k s + atol`` and, if ``lossless``,
    ``|albedo - 1| <= k s + atol`` (``k = 5``, ``atol = 1e-4`` by default: a false alarm
    is a 5-sigma event, and a loss or gain of a few tenths of a percent is caught at the
    default ``n``). Non-finite or negative weights fail.

    >>> from drjit.auto import Array3f
    >>> from drpt.render.bsdf import diffuse
    >>> p = diffuse.DiffuseParams(Array3f(1.0))
    >>> furnace(lambda wi, u1, u2: diffuse.sample(p, wi, u1, u2), [(0, 0, 1)], lossless=True).passed
    True
    """
    from drjit.auto import Array2f, Array3f, Float

    rng = np.random.default_rng(seed)
    albedo, stderr, problems = [], [], []
    for wi in wis:
        d = np.asarray(wi, np.float64)
        d = d / np.linalg.norm(d)
        u = rng.random((3, n)).astype(np.float32)
        w_in = Array3f(*(Float(np.full(n, c, np.float32)) for c in d))
        res = sample(w_in, Float(u[0]), Array2f(Float(u[1]), Float(u[2])))
        w = np.array(getattr(res, "weight", res), np.float64).reshape(3, -1)
        if not np.all(np.isfinite(w)) or np.any(w < 0.0):
            problems.append(f"wi {tuple(d.round(4))}: non-finite or negative weights")
            w = np.nan_to_num(np.abs(w), nan=1e30, posinf=1e30)
        a, s = w.mean(axis=1), w.std(axis=1) / math.sqrt(w.shape[1])
        albedo.append(a)
        stderr.append(s)
        lim = k * s + atol
        if np.any(a > 1.0 + lim):
            problems.append(f"wi {tuple(d.round(4))}: albedo {a.round(5)} > 1 (+/- {s.round(5)})")
        if lossless and np.any(np.abs(a - 1.0) > lim):
            problems.append(f"wi {tuple(d.round(4))}: albedo {a.round(5)} != 1 (+/- {s.round(5)})")
    albedo_a, stderr_a = np.array(albedo), np.array(stderr)
    msg = "; ".join(problems) if problems else f"pass: albedo {albedo_a.round(5).tolist()}"
    return Furnace(albedo_a, stderr_a, not problems, msg)


# ------------------------------------------------------------------ drpt vs Mitsuba, per block
#: independent Mitsuba renders from which :func:`render_both` estimates Mitsuba's variance
BATCHES = 8


def block_z(x, var_x, ref, var_ref, block=8):
    """Per ``block x block`` pixel block and channel, the difference of the block means of
    ``x`` and ``ref`` over the combined standard error ``sqrt(mean(var_x) / n +
    mean(var_ref) / n)`` (``n = block^2``; ``var_*``: the per-pixel variance of each pixel's
    mean). Images are ``(H, W, C)``; a partial block at the right or bottom edge is left
    out. Returns the z image ``(H // block, W // block, C)``. The tests require
    ``max |z| < 4.5`` (:func:`assert_agree`) or a similar documented bound.

    >>> z = block_z(r.image, r.variance, ref, ref_var)  # doctest: +SKIP
    """
    H, W, C = x.shape
    H2, W2 = H - H % block, W - W % block

    def blk(a):
        a = a[:H2, :W2]
        return a.reshape(H2 // block, block, W2 // block, block, C).mean((1, 3))

    n = block * block
    var = blk(var_x) / n + blk(var_ref) / n
    return (blk(x) - blk(ref)) / np.sqrt(np.maximum(var, 1e-30))


def mitsuba_runs(scene, W, H, spp, max_depth=-1, bsdf="phong", seed=1, rfilter="box",
                 batches=BATCHES):
    """``batches`` independent Mitsuba renders (float64, ``(B, H, W, 3)``) of the exported
    scene (:func:`drpt.export.mitsuba.to_mitsuba_dict`), ``spp / batches`` samples per pixel
    each, seeds ``seed + 100 + 7919 k``; the film's pixel filter is ``rfilter``."""
    mi = mitsuba()
    per = max(1, spp // batches)
    ms = mi.load_dict(to_mitsuba_dict(scene, W, H, per, max_depth=max_depth, seed=seed + 100,
                                      bsdf=bsdf, rfilter=rfilter))
    return np.stack([np.asarray(mi.render(ms, spp=per, seed=seed + 100 + 7919 * k), np.float64)
                     for k in range(batches)])


def render_both(scene, W, H, spp, max_depth=-1, bsdf="phong", seed=1):
    """Render a loaded drpt ``scene`` with drpt and with Mitsuba (:func:`mitsuba_runs`) at
    ``W x H`` and ``spp``. Returns ``(drpt RenderResult, Mitsuba mean image, Mitsuba
    variance of the mean)``, the arguments of :func:`assert_agree`.

    >>> r, ref, ref_var = render_both(load_scene("scenes/cornell.txt"), 32, 32, 64)  # doctest: +SKIP
    >>> assert_agree(r, ref, ref_var)  # doctest: +SKIP
    """
    r = Renderer(scene, RenderOptions(width=W, height=H, spp=spp, seed=seed, bsdf=bsdf,
                                      progress=False, path=PathOptions(max_depth=max_depth))).render()
    runs = mitsuba_runs(scene, W, H, spp, max_depth=max_depth, bsdf=bsdf, seed=seed)
    ref = runs.mean(0)
    ref_var = runs.var(0, ddof=1) / BATCHES
    return r, ref.astype(np.float32), ref_var.astype(np.float32)


def block_z_correlated(x, var_x, runs, block=4):
    """:func:`block_z` of drpt's image (independent pixels, per-pixel variance ``var_x``)
    against the mean of Mitsuba's ``runs`` (:func:`mitsuba_runs`) whose pixels may be
    correlated (a splatting pixel filter shares each sample among neighbours, so a block
    mean's variance exceeds the mean of its pixels' variances over the pixel count).

    Mitsuba's block variance is ``f_c * mean(var_pixels) / n``: the naive figure from the
    batches' per-pixel variances (many degrees of freedom) times a per-channel correlation
    factor ``f_c`` estimated over the whole image, ``sum over blocks of the batch variance
    of the block means / sum over blocks of the naive figure`` (the ratio of two sums over
    all blocks, so it is stable, though each block's own batch variance has only ``B - 1``
    degrees of freedom). ``f_c`` is ~1 for a box filter and grows towards ``1 / J``
    (:mod:`drpt.filters`) as blocks grow past the filter. A variance floor of ``(1e-5 *
    |value|)^2`` keeps pixels without noise (both sides constant) from dividing float32
    rounding by zero. Returns ``(z, f)``."""
    H, W, C = x.shape
    H2, W2 = H - H % block, W - W % block

    def blk(a):
        a = a[..., :H2, :W2, :]
        return a.reshape(*a.shape[:-3], H2 // block, block, W2 // block, block, C).mean((-4, -2))

    n, B = block * block, runs.shape[0]
    ref = runs.mean(0)
    naive = blk(runs.var(0, ddof=1) / B) / n
    batch = blk(runs).var(0, ddof=1) / B
    f = batch.sum((0, 1)) / np.maximum(naive.sum((0, 1)), 1e-30)
    floor = (1e-5 * np.maximum(np.abs(blk(x)), np.abs(blk(ref)))) ** 2
    var = blk(var_x) / n + f * naive + floor
    return (blk(x) - blk(ref)) / np.sqrt(var), f


def agreement(a, b, block=8, floor=0.0) -> tuple[float, float]:
    """Two renders' agreement (``RenderResult``-like: ``image`` and per-pixel ``variance``):
    the largest :func:`block_z` over the blocks and channels and the largest z of the
    channels' image means, each ``|z|``. ``floor``: a relative floor on the blocks' variances
    (``variance + (floor * image)^2``: pixels of one constant value, such as a background,
    have no variance but float rounding)."""
    z = block_z(a.image, a.variance + (floor * a.image) ** 2, b.image, b.variance + (floor * b.image) ** 2,
                block=block)
    return float(np.abs(z).max()), float(np.abs(mean_z(a, b.image, b.variance)).max())


def mean_z(r, ref, var) -> np.ndarray:
    """z of the difference of a render's (``image``, ``variance``) and a reference's (``ref``,
    per-pixel ``var``) image means, per channel (a bias of a fraction of a percent over the
    whole image shows here before it shows in any one block)."""
    n = ref.shape[0] * ref.shape[1]
    se = np.sqrt(r.variance.mean((0, 1)) / n + var.mean((0, 1)) / n)
    return (r.image.astype(np.float64).mean((0, 1)) - ref.mean((0, 1))) / se


def assert_agree(r, ref, ref_var, zmax=4.5, block=8):
    """Assert that a drpt ``RenderResult`` ``r`` is finite (no non-finite samples) and agrees
    with a reference mean ``ref`` of per-pixel variance ``ref_var``: every
    :func:`block_z` has ``|z| < zmax`` (4.5 by default). Returns the z image."""
    assert np.all(np.isfinite(r.image)) and r.nonfinite == 0
    z = block_z(r.image, r.variance, ref, ref_var, block=block)
    assert np.abs(z).max() < zmax, f"max |z| = {np.abs(z).max():.2f}"
    return z


# ------------------------------------------------------------------ Mitsuba's render z-test
#: linear sRGB -> CIE XYZ (D65), the matrix of Mitsuba's ``srgb_to_xyz``; :func:`z_test`
#: applies it to the images and (as Mitsuba's ``Bitmap.convert`` does) to the variance images
SRGB_TO_XYZ = np.array([[0.412453, 0.357580, 0.180423],
                        [0.212671, 0.715160, 0.072169],
                        [0.019334, 0.119193, 0.950227]])


def to_xyz(rgb: np.ndarray) -> np.ndarray:
    """Linear sRGB ``(..., 3)`` -> CIE XYZ (:data:`SRGB_TO_XYZ`)."""
    return rgb @ SRGB_TO_XYZ.T


@dataclass
class ZTest:
    """The result of :func:`z_test`."""

    passed: bool
    fraction: float  # of pixel channels with p > alpha
    alpha: float
    min_p: float
    spp: int

    def __str__(self) -> str:
        return (f"{'pass' if self.passed else 'FAIL'}: {self.fraction:.4%} of pixel channels "
                f"p > {self.alpha:.2e} (need 99.75%), min p {self.min_p:.2e}, {self.spp} spp")


def z_test(image_rgb: np.ndarray, spp: int, ref_rgb: np.ndarray, ref_var_rgb: np.ndarray,
           significance: float = 0.01) -> ZTest:
    """Mitsuba's render-test z-test (``src/render/tests/test_renders.py``) of an image
    (linear RGB, ``(H, W, 3)``) rendered at ``spp`` against a reference and the reference's
    per-*sample* variance (both linear RGB, as Mitsuba's ``moment`` integrator writes them).

    In XYZ, per pixel and channel, ``z = |mean - ref| * sqrt(spp / max(ref_var, 1e-4))``;
    two-sided p-values against the Sidak-corrected level ``alpha = 1 - (1 - significance)
    ** (1 / pixels)``; passes when at least 99.75% of the pixel channels have ``p > alpha``.
    Assumes the image's per-sample variance is close to the reference's. Returns a
    :class:`ZTest`.

    >>> print(z_test(result.image, 64, ref, ref_var))  # doctest: +SKIP
    pass: 100.0000% of pixel channels p > 1.57e-06 (need 99.75%), min p 1.2e-03, 64 spp
    """
    img = to_xyz(np.asarray(image_rgb, np.float64)[..., :3])
    ref = to_xyz(ref_rgb)
    var = np.maximum(to_xyz(ref_var_rgb), 1e-4)
    z = np.abs(img - ref) * np.sqrt(spp / var)
    p = np.array([math.erfc(v / math.sqrt(2.0)) for v in z.ravel()]).reshape(z.shape)
    pixels = img.shape[0] * img.shape[1]
    alpha = 1.0 - (1.0 - significance) ** (1.0 / pixels)
    ok = p > alpha
    frac = float(np.count_nonzero(ok)) / (3 * pixels)
    return ZTest(frac >= 0.9975, frac, alpha, float(p.min()), spp)
