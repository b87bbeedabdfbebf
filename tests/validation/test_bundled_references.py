"""Bundled scenes against their committed Mitsuba references
(drpt.tools.reference): the Cornell box read as Cook-Torrance, the
env-lit car showcase by day and at dusk, the 510k-triangle dining room, and the
Cornell box with a glass sphere of scattering liquid and a fog layer (drpt's volpath
against Mitsuba's, the scene exported with its media).

Statistic (as in tests/validation/test_render_mitsuba.py and test_newscene.py): drpt
renders at the reference's size with a fixed seed; the image is cut into
blocks and for each block and channel

    z = (mean_drpt - mean_ref) / sqrt(var_drpt + var_ref + (1e-3 mean_ref)^2)

Unbiased renderers give z ~ N(0, 1); we require max |z| < 4.5 (~1e-3 false
alarms per test under normality).

* var_ref: the showcase and dining-room references were rendered in 16
  batches, whose spread is committed (``*_var.exr``); for the Cornell box,
  drpt's per-sample variance over the reference's spp.
* var_drpt: drpt's own estimate, but at least the reference's per-sample
  variance over drpt's spp. Sunlight through the car's glass (camera -> glass
  -> interior -> glass -> sun, reachable only by BSDF sampling) makes
  heavy-tailed samples: at 64 spp drpt mostly misses them, so its own variance
  estimate *and* its mean are low there, and with its own variance alone the
  windows gave |z| up to 48 against the 4096-spp reference. Live renders at
  4 x 4096 spp of each renderer agree there (per-pixel |z| < 2.6 along the
  windows): not a bias.
* the 1e-3 floor: blocks of directly seen sky have a variance of ~1e-9 (only
  the sub-pixel position varies) and differ systematically by up to 5e-4 of
  their value (measured over seeds; cause not traced, sub-0.1%); that is not
  what these tests are about.

Each test has a negative control: the same statistic on the same render must
flag a uniform brightness bias of a few percent (the size each test resolves
is in its comment), so the tests can fail.

The dining room (git-ignored, 510k triangles) is reused from scenes/diningroom
when it is there at the reference's triangle count, else generated into a
temporary folder; scenes are loaded once per session (the ``reference_scene``
fixture in conftest.py, shared with test_converge.py).
"""


import numpy as np
import pytest

from drpt.imageio import read_image
from drpt.options import RenderOptions
from drpt.render.renderer import Renderer
from drpt.tools.reference import REFERENCES, reference_path, variance_path

ZMAX = 4.5
# Blocks of directly seen sky have a pixel variance of ~1e-9 (only the sub-pixel
# position varies); there drpt and Mitsuba differ systematically by up to ~5e-4 of the
# value (measured over seeds 2-6; cause not traced). A standard error
# floor of 1e-3 of the reference keeps such differences from counting as bias; every
# bias the tests are about is tens of times larger.
REL_TOL = 1e-3
#: drpt's spp for the Cornell box with media
SPP_MEDIA = 1024


def blocks(a, block):
    H, W, C = a.shape
    a = a[:H - H % block, :W - W % block]
    return a.reshape(H // block, block, W // block, block, C).mean((1, 3))


def render_and_z(name, spp, seed, block, reference_scene):
    """drpt at the reference's settings: (result, max |z|, z(scale, first_row)) where the
    last gives max |z| of the render with a brightness bias (negative controls)."""
    scene_file, W, H, ref_spp, depth, mode = REFERENCES[name]
    scene = reference_scene(scene_file)
    assert depth == -1
    ref = read_image(reference_path(name))
    assert ref.shape == (H, W, 3) and np.all(np.isfinite(ref))
    # (a scene with media renders with volpath, as its reference does with Mitsuba's)
    r = Renderer(scene, RenderOptions(width=W, height=H, spp=spp, seed=seed, bsdf=mode, progress=False,
                                      integrator="volpath" if scene.media else "path")).render()
    assert r.nonfinite == 0 and np.all(np.isfinite(r.image))
    n = block * block
    var_x = blocks(r.variance, block) / n
    if variance_path(name).exists():
        # The reference's measured variance; drpt's block variance is the larger of its
        # own estimate and the reference's per-sample variance over drpt's spp.
        var_ref = blocks(read_image(variance_path(name)), block) / n
        var_x = np.maximum(var_x, var_ref * ref_spp / spp)
    else:
        var_ref = var_x * spp / ref_spp  # the same per-sample variance over ref_spp
    diff, mean = blocks(r.image, block) - blocks(ref, block), blocks(r.image, block)
    var_ref = var_ref + (REL_TOL * blocks(ref, block)) ** 2

    def z(scale=1.0, first_row=0):
        """max |z| with drpt's blocks from block row ``first_row`` on scaled by ``scale``."""
        s = np.ones((diff.shape[0], 1, 1))
        s[first_row:] = scale
        return float(np.abs((diff + (s - 1) * mean) / np.sqrt(s**2 * var_x + var_ref)).max())

    return r, z(), z


@pytest.mark.slow
def test_cornellbox_cook_torrance_matches_reference(reference_scene):
    # max |z| 2.4-3.7 over seeds 1-3; 2% bias: |z| > 5.6
    r, z, z_of = render_and_z("cornellbox_ct", spp=64, seed=11, block=16,
                              reference_scene=reference_scene)
    assert z < ZMAX, z
    assert z_of(1.02) > ZMAX and z_of(0.98) > ZMAX  # negative control


@pytest.mark.slow
@pytest.mark.parametrize("name", ["showcase_day", "showcase_dusk"])
def test_showcase_matches_reference(name, reference_scene):
    # max |z| over seeds 1-5: day 1.9-2.6, dusk 2.6-4.2. Negative control: a 3% bias on
    # the car and ground alone (block rows 3.. of 9, below the horizon) gives |z| 6-9.
    r, z, z_of = render_and_z(name, spp=64, seed=1, block=8,
                              reference_scene=reference_scene)
    assert z < ZMAX, z
    assert z_of(1.03, first_row=3) > ZMAX and z_of(0.97, first_row=3) > ZMAX


@pytest.mark.slow
def test_diningroom_matches_reference(reference_scene):
    # Slowest test of this file: generating (when scenes/diningroom is missing, ~6 s),
    # loading (~6-12 s) and the BVH build (~8-17 s) of 510k triangles; the 32-spp render
    # itself takes a few seconds. max |z| 1.6-2.1 over seeds 1-3 (embree and bvh alike);
    # a 5% bias gives 4.4-6.1 brighter and 6.2-7.0 darker, seed 1 the weakest control
    # (4.4-4.7), seed 2 5.9-6.1 and 6.6-6.7, hence seed 2.
    r, z, z_of = render_and_z("diningroom", spp=32, seed=2, block=24,
                              reference_scene=reference_scene)
    assert z < ZMAX, z
    assert z_of(1.05) > ZMAX and z_of(0.95) > ZMAX  # negative control


@pytest.mark.slow
def test_cornellbox_media_matches_reference(reference_scene):
    # The glass sphere of scattering liquid and the fog layer (media exported to Mitsuba's
    # volpath). max |z| 1.9-2.3 over seeds 1-3; a 2% bias gives 6.7-8.3.
    r, z, z_of = render_and_z("cornellbox_media", spp=SPP_MEDIA, seed=1, block=8,
                              reference_scene=reference_scene)
    assert z < ZMAX, z
    assert z_of(1.02) > ZMAX and z_of(0.98) > ZMAX  # negative control
