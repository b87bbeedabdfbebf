"""drpt against Mitsuba 3 on the bundled Cornell box.

Two statistics, both with fixed seeds:

* relMSE = mean over pixels and channels of (x - ref)^2 / (ref^2 + 1e-2),
  the usual relative MSE. It measures noise plus bias; the bound 0.01 is
  the issue's ("well under 0.01"); drpt measures ~7e-4 at 128x128, 256 spp.
* block z-scores (drpt/testing.py): the image is cut into 16x16-pixel
  blocks; for each block and channel z = (mean_drpt - mean_ref) /
  sqrt(var_drpt + var_ref), with drpt's per-pixel variance estimate; for the
  8192-spp reference the same per-sample variance over its own spp (one
  area light, the two renderers' per-sample variances are alike), for live
  Mitsuba renders the variance across independent batches. Unbiased renderers give z ~
  N(0, 1); we require max |z| < 4.5 over all 192 blocks (a false alarm
  probability of ~1e-3 under normality). A bias of 1-2% in a bright region
  fails this; noise does not.
"""


import numpy as np
import pytest

from drpt.cli import main
from drpt.imageio import read_image
from drpt.options import RenderOptions
from drpt.render.renderer import Renderer
from drpt.scene import load_scene
from drpt.testing import assert_agree, block_z, render_both
from drpt.tools.reference import REFERENCES, reference_path


def rel_mse(x, ref):
    return float(np.mean((x - ref) ** 2 / (ref**2 + 1e-2)))


@pytest.fixture(scope="module")
def reference():
    _, w, h, spp, depth, _ = REFERENCES["cornellbox"]
    return read_image(reference_path("cornellbox")), spp


@pytest.mark.slow
def test_seed_flags_render_matches_mitsuba_reference(tmp_path, reference, capsys, cornell):
    ref, _ = reference
    out = tmp_path / "cornell.exr"
    code = main(["render", "-input", str(cornell), "-size", "128", "128", "-output", str(out),
                 "-spp", "256", "-MonteCarlo", "-SpatialTree", "--quiet"])
    assert code == 0
    img = read_image(out)
    assert img.shape == ref.shape and np.all(np.isfinite(img))
    assert rel_mse(img, ref) < 0.01
    # The whole-image mean is a 4M-sample average: within 0.5% per channel.
    assert np.allclose(img.mean((0, 1)), ref.mean((0, 1)), rtol=5e-3)
    assert "Msamples/s" in capsys.readouterr().out


def test_no_bias_against_mitsuba_reference(reference, cornell):
    ref, ref_spp = reference
    spp = 64
    r = Renderer(load_scene(cornell), RenderOptions(width=128, height=128, spp=spp, seed=7,
                                                    progress=False)).render()
    z = block_z(r.image, r.variance, ref, r.variance * spp / ref_spp, block=16)
    assert np.abs(z).max() < 4.5, np.abs(z).max()
    # Negative control: the same statistic flags a 2% brightness bias.
    z_biased = block_z(r.image * 1.02, r.variance * 1.02**2, ref, r.variance * spp / ref_spp,
                       block=16)
    assert np.abs(z_biased).max() > 4.5


@pytest.mark.slow
@pytest.mark.mitsuba
def test_live_mitsuba_export_agrees_at_fixed_depth(cornell):
    # Non-square, truncated depth (exercises the depth convention), Mitsuba
    # rendered now from the in-memory export.
    scene = load_scene(cornell)
    for depth in (2, 3):
        r, ref, ref_var = render_both(scene, 64, 48, 256, max_depth=depth, seed=3)
        assert_agree(r, ref, ref_var, block=16)
