"""Shared render-comparison helpers for tests: drpt vs Mitsuba 3 on one scene.

``block_z`` is the statistic documented in tests/test_render_mitsuba.py:
per 8x8 (or ``block``) pixel block and channel, the difference of means over
the combined standard error. drpt reports its per-pixel variance; Mitsuba's
is estimated from ``BATCHES`` independent renders (different seeds) of
``spp / BATCHES`` samples each, since its per-sample variance differs from
drpt's (e.g. it picks one light per vertex where drpt samples every delta
light).
"""

from __future__ import annotations

import numpy as np

from drpt.options import PathOptions, RenderOptions
from drpt.render.renderer import Renderer


def block_z(x, var_x, ref, var_ref, block=8):
    H, W, C = x.shape
    H2, W2 = H - H % block, W - W % block

    def blk(a):
        a = a[:H2, :W2]
        return a.reshape(H2 // block, block, W2 // block, block, C).mean((1, 3))

    n = block * block
    var = blk(var_x) / n + blk(var_ref) / n
    return (blk(x) - blk(ref)) / np.sqrt(np.maximum(var, 1e-30))


BATCHES = 8


def render_both(scene, W, H, spp, max_depth=-1, bsdf="phong", seed=1):
    """(drpt RenderResult, Mitsuba mean image, Mitsuba variance of the mean)."""
    import mitsuba as mi

    from drpt.backend import mitsuba_variant
    mi.set_variant(mitsuba_variant())  # before drpt renders, as it always was here
    r = Renderer(scene, RenderOptions(width=W, height=H, spp=spp, seed=seed, bsdf=bsdf,
                                      progress=False, path=PathOptions(max_depth=max_depth))).render()
    return (r, *render_mitsuba(scene, W, H, spp, max_depth=max_depth, bsdf=bsdf, seed=seed))


def render_mitsuba(scene, W, H, spp, max_depth=-1, bsdf="phong", seed=1):
    """Mitsuba's half of :func:`render_both`: the export rendered in ``BATCHES`` batches
    (seeds ``seed + 100 + 7919 k``); (mean image, variance of the mean), float32."""
    import mitsuba as mi

    from drpt.backend import mitsuba_variant
    mi.set_variant(mitsuba_variant())
    from drpt.export.mitsuba import to_mitsuba_dict

    per = max(1, spp // BATCHES)
    ms = mi.load_dict(to_mitsuba_dict(scene, W, H, per, max_depth=max_depth, seed=seed + 100,
                                      bsdf=bsdf))
    runs = np.stack([np.asarray(mi.render(ms, spp=per, seed=seed + 100 + 7919 * k), np.float64)
                     for k in range(BATCHES)])
    ref = runs.mean(0)
    ref_var = runs.var(0, ddof=1) / BATCHES
    return ref.astype(np.float32), ref_var.astype(np.float32)


def assert_agree(r, ref, ref_var, zmax=4.5, block=8):
    assert np.all(np.isfinite(r.image)) and r.nonfinite == 0
    z = block_z(r.image, r.variance, ref, ref_var, block=block)
    assert np.abs(z).max() < zmax, f"max |z| = {np.abs(z).max():.2f}"
    return z
