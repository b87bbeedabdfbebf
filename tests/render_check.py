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


def mitsuba_runs(scene, W, H, spp, max_depth=-1, bsdf="phong", seed=1, rfilter="box",
                 batches=BATCHES):
    """``batches`` independent Mitsuba renders (float64, ``(B, H, W, 3)``) of
    the exported scene, ``spp / batches`` samples per pixel each, seeds
    ``seed + 100 + 7919 k``; the film's pixel filter is ``rfilter``."""
    import mitsuba as mi

    from drpt.backend import mitsuba_variant
    mi.set_variant(mitsuba_variant())
    from drpt.export.mitsuba import to_mitsuba_dict

    per = max(1, spp // batches)
    ms = mi.load_dict(to_mitsuba_dict(scene, W, H, per, max_depth=max_depth, seed=seed + 100,
                                      bsdf=bsdf, rfilter=rfilter))
    return np.stack([np.asarray(mi.render(ms, spp=per, seed=seed + 100 + 7919 * k), np.float64)
                     for k in range(batches)])


def render_both(scene, W, H, spp, max_depth=-1, bsdf="phong", seed=1):
    """(drpt RenderResult, Mitsuba mean image, Mitsuba variance of the mean)."""
    r = Renderer(scene, RenderOptions(width=W, height=H, spp=spp, seed=seed, bsdf=bsdf,
                                      progress=False, path=PathOptions(max_depth=max_depth))).render()
    runs = mitsuba_runs(scene, W, H, spp, max_depth=max_depth, bsdf=bsdf, seed=seed)
    ref = runs.mean(0)
    ref_var = runs.var(0, ddof=1) / BATCHES
    return r, ref.astype(np.float32), ref_var.astype(np.float32)


def block_z_correlated(x, var_x, runs, block=4):
    """``block_z`` of drpt's image (independent pixels, per-pixel variance
    ``var_x``) against the mean of Mitsuba's ``runs`` whose pixels may be
    correlated (a splatting pixel filter shares each sample among
    neighbours, so a block mean's variance exceeds the mean of its pixels'
    variances over the pixel count).

    Mitsuba's block variance is ``f_c * mean(var_pixels) / n``: the naive
    figure from the batches' per-pixel variances (many degrees of freedom)
    times a per-channel correlation factor ``f_c`` estimated over the whole
    image, ``sum over blocks of the batch variance of the block means / sum
    over blocks of the naive figure`` (the ratio of two sums over all
    blocks, so it is stable, though each block's own batch variance has only
    ``B - 1`` degrees of freedom). ``f_c`` is ~1 for a box filter and grows
    towards ``1 / J`` (:mod:`drpt.filters`) as blocks grow past the filter.
    A variance floor of ``(1e-5 * |value|)^2`` keeps pixels without noise
    (both sides constant) from dividing float32 rounding by zero.
    Returns ``(z, f)``."""
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


def _quad(x0, y0, x1, y1, z, mat):
    a, b, c, d = (x0, y0, z), (x1, y0, z), (x1, y1, z), (x0, y1, z)

    def f(p):
        return " ".join(repr(float(v)) for v in p)

    return (f"MaterialIndex {mat}\nTriangle {{ vertex0 {f(a)} vertex1 {f(b)} vertex2 {f(c)} }}\n"
            f"Triangle {{ vertex0 {f(a)} vertex1 {f(c)} vertex2 {f(d)} }}\n", 2)


def edge_scene(aperture=None, spheres=False) -> str:
    """An edge-rich scene for pixel-filter and camera tests (drpt's format):
    a grey wall at z = 0 seen head-on from z = 5 (40 degrees: about 0.076
    world units per pixel at 48 pixels), lit by a point light, with thin
    vertical and horizontal stripes (red diffuse, white and blue emitters,
    0.05 to 0.22 units wide) and two emitters just outside the right and top
    edges of the frame (0.2 pixels beyond it: only a filter that reaches
    beyond the image sees them). ``aperture = (radius, focus distance)``
    makes the camera a thin lens; ``spheres`` adds a red sphere at distance
    3 and a small blue emitting one at 2.7."""
    objs = [_quad(-3, -3, 3, 3, 0.0, 0)]
    if spheres:
        objs.append(("MaterialIndex 1\nSphere { center -0.3 0.2 2 radius 0.35 }\n"
                     "MaterialIndex 3\nSphere { center 0.5 -0.45 2.3 radius 0.12 }\n", 2))
    for k, x in enumerate([-1.6, -1.1, -0.62, -0.2, 0.33, 0.71, 1.0, 1.3]):
        objs.append(_quad(x, -1.7, x + 0.05 + 0.04 * (k % 4), 1.0, 0.01, 1 + k % 3))
    for k, y in enumerate([-1.4, -0.9, 0.9, 1.25]):
        objs.append(_quad(-1.9, y, 1.9, y + 0.06 + 0.05 * k, 0.02, 1 + (k + 1) % 3))
    objs.append(_quad(1.835, -1.5, 2.5, 1.5, 0.01, 2))  # just beyond the right edge (x = 1.82)
    objs.append(_quad(-1.5, 1.835, 1.5, 2.5, 0.01, 3))  # just beyond the top edge
    lens = "" if aperture is None else f" apertureRadius {aperture[0]} focusDistance {aperture[1]}"
    return (f"PerspectiveCamera {{ center 0 0 5 direction 0 0 -1 up 0 1 0 angle 40{lens} }}\n"
            "Lights { numLights 1 PointLight { position 0.5 0.8 3 color 12 12 12 } }\n"
            "Materials { numMaterials 4\n"
            "  Material { diffuseColor 0.6 0.6 0.6 }\n"
            "  Material { diffuseColor 0.9 0.15 0.1 }\n"
            "  Material { diffuseColor 0 0 0 Ke 3 3 3 }\n"
            "  Material { diffuseColor 0.05 0.05 0.05 Ke 0.5 2.5 4 }\n}\n"
            f"Group {{ numObjects {sum(o[1] for o in objs)}\n{''.join(o[0] for o in objs)}}}\n")


def assert_agree(r, ref, ref_var, zmax=4.5, block=8):
    assert np.all(np.isfinite(r.image)) and r.nonfinite == 0
    z = block_z(r.image, r.variance, ref, ref_var, block=block)
    assert np.abs(z).max() < zmax, f"max |z| = {np.abs(z).max():.2f}"
    return z
