"""Adapters between drpt's samplers (drjit.auto types) and Mitsuba's
``mitsuba.chi2.ChiSquareTest`` (llvm_ad_rgb types), via numpy."""

from __future__ import annotations

import os
import tempfile

import numpy as np


def mitsuba():
    import mitsuba as mi

    from drpt.backend import mitsuba_variant
    mi.set_variant(mitsuba_variant())
    return mi


def to_drpt(v, cls):
    from drjit.auto import Float

    a = np.array(v, dtype=np.float32)
    if a.ndim == 1:
        return cls(Float(a)) if cls is not Float else Float(a)
    return cls(*(Float(np.ascontiguousarray(a[i])) for i in range(a.shape[0])))


def to_mitsuba_vec3(v):
    mi = mitsuba()
    a = np.array(v, dtype=np.float32)
    return mi.Vector3f(a[0], a[1], a[2])


def to_mitsuba_float(x):
    mi = mitsuba()
    return mi.Float(np.array(x, dtype=np.float32))


def run_chi2(sample, pdf, sample_dim=2, sample_count=400_000, res=61, seed=0, ires=None):
    """Chi-square test of a direction sampler on the sphere.

    ``sample(u: drjit.auto ArrayNf) -> drjit.auto Array3f`` and
    ``pdf(w: drjit.auto Array3f) -> drjit.auto Float``. Mitsuba's test rejects
    at significance 1% (after a Sidak correction for the number of tests it
    runs); returns (passed, message). ``ires``: the points per bin side at which
    the pdf is integrated (None: Mitsuba's default, 4; a density with a sharp edge
    inside bins needs more).
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


def spherical_chi2(sample_func, pdf_func, **kwargs):
    """Mitsuba's ``ChiSquareTest`` on the sphere with Mitsuba-typed
    ``sample_func``/``pdf_func`` and its other arguments (``sample_dim``,
    ``sample_count``, ``res``, ``ires``, ``seed``), run in a temporary
    directory (on failure Mitsuba writes chi2_data.py into the working
    directory). Returns (passed, messages)."""
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


def export_bsdf(kind, two_sided=False, **params):
    """drpt's Mitsuba dict (drpt.export.mitsuba_bsdf) of a ``kind`` spec with
    ``params`` (defaults filled in), wrapped in ``twosided`` if asked."""
    from drpt.export.mitsuba_bsdf import to_mitsuba
    from drpt.shading import BSDFSpec, complete

    spec = BSDFSpec(kind, params)
    if two_sided:
        spec = BSDFSpec("twosided", children=[spec])
    return to_mitsuba(complete(spec))
