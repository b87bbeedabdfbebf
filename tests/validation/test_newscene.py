"""The seed's "newscene" (Cornell box + metal/rough spheres, Cook-Torrance)
and its hard case (gold sphere at metalness 0.9, roughness 0.9) against
committed Mitsuba references (drpt.tools.reference).

* no bias: 16x16 block z-scores against the 4096-spp reference, max < 4.5;
* noise no worse than Mitsuba's: relMSE at 64 spp at most 1.25x that of a
  64-spp Mitsuba render of the same export (measured: 0.024 vs 0.024);
* no more speckles than Mitsuba: a "speckle" is a pixel more than 4x (+0.05)
  brighter than its 3x3 median where the reference is not (white), or below
  1/4 of a median above 0.05 where the reference is not (black). The seed's
  renders are full of both. Unidirectional path tracing at 64 spp makes some
  of each by chance: bright pixels from caustic paths (floor -> glossy sphere
  -> light) and dark pixels in dim corners lit mostly through rare paths;
  with the seed's alpha = Roughness^2 the spheres are sharp and caustics
  common. Four renders (seeds 3-6) of each renderer are counted; drpt's
  totals must stay within 2x Mitsuba's plus a Poisson allowance (8 white,
  3 black). Measured: newscene Mitsuba 49 white / 10 black, drpt 81 / 3;
  newscene_hard 51 / 9 and 75 / 3: drpt makes more bright and fewer dark
  speckles (it estimates every light at each vertex; Mitsuba picks one).
"""


import numpy as np
import pytest
from scipy.ndimage import median_filter

from drpt.imageio import read_image
from drpt.options import RenderOptions
from drpt.render.renderer import Renderer
from drpt.scene import load_scene
from drpt.testing import block_z
from drpt.tools.reference import REFERENCES, reference_path


def speckles(x, ref):
    lx, lr = x.mean(2), ref.mean(2)
    mx, mr = median_filter(lx, 3, mode="nearest"), median_filter(lr, 3, mode="nearest")
    white = (lx > 4 * mx + 0.05) & (lr < 2 * mr + 0.05)
    black = (lx < 0.25 * mx) & (mx > 0.05) & (lr > 0.5 * mr)
    return int(white.sum()), int(black.sum())


def rel_mse(x, ref):
    return float(np.mean((x - ref) ** 2 / (ref**2 + 1e-2)))


@pytest.mark.slow
@pytest.mark.mitsuba
@pytest.mark.parametrize("name", ["newscene", "newscene_hard"])
def test_newscene_converges_to_mitsuba_without_speckles(name, repo):
    mi = pytest.importorskip("mitsuba")
    from drpt.backend import mitsuba_variant
    mi.set_variant(mitsuba_variant())
    from drpt.export.mitsuba import to_mitsuba_dict

    scene_file, W, H, ref_spp, depth, mode = REFERENCES[name]
    ref = read_image(reference_path(name))
    scene = load_scene(repo / scene_file)
    spp = 64
    r = Renderer(scene, RenderOptions(width=W, height=H, spp=spp, seed=3, bsdf=mode,
                                      progress=False)).render()
    assert r.nonfinite == 0 and np.all(np.isfinite(r.image))
    z = block_z(r.image, r.variance, ref, r.variance * spp / ref_spp, block=16)
    assert np.abs(z).max() < 4.5, np.abs(z).max()

    mits = np.asarray(mi.render(mi.load_dict(to_mitsuba_dict(scene, W, H, spp, bsdf=mode,
                                                             seed=3))), np.float32)
    assert rel_mse(r.image, ref) < 1.25 * rel_mse(mits, ref)
    white, black = speckles(r.image, ref)
    mw, mb = speckles(mits, ref)
    ms = mi.load_dict(to_mitsuba_dict(scene, W, H, spp, bsdf=mode, seed=3))
    for seed in (4, 5, 6):
        img = Renderer(scene, RenderOptions(width=W, height=H, spp=spp, seed=seed, bsdf=mode,
                                            progress=False)).render().image
        w, b = speckles(img, ref)
        white, black = white + w, black + b
        w, b = speckles(np.asarray(mi.render(ms, seed=seed), np.float32), ref)
        mw, mb = mw + w, mb + b
    assert white <= 2 * mw + 8 and black <= 2 * mb + 3, (white, black, mw, mb)


def test_speckle_detector_finds_speckles():
    # Negative control: salt-and-pepper noise on the reference is found.
    ref = read_image(reference_path("newscene"))
    noisy = ref.copy()
    rng = np.random.default_rng(0)
    idx = rng.choice(ref.shape[0] * ref.shape[1], 40, replace=False)
    ys, xs = np.unravel_index(idx, ref.shape[:2])
    noisy[ys[:20], xs[:20]] = 5.0
    noisy[ys[20:], xs[20:]] = 0.0
    white, black = speckles(noisy, ref)
    assert white >= 15 and black >= 5
