"""drpt against Mitsuba 3 on the mixed-material test scenes, rendered from drpt's export.

Scenes (generated into a temporary folder by :mod:`drpt.tools.scenegen`):

* ``materials_cornell``: Cornell box with a gold and a plastic ``principled``,
  a frosted ``roughdielectric`` block, a smooth ``dielectric`` water slab and
  diffuse walls;
* ``materials_cornell_conductor``: the same with the sphere a GGX
  ``roughconductor``;
* ``veach_mis``: four GGX ``roughconductor`` plates (alpha 0.005 .. 0.1)
  reflecting four equal-power sphere lights (radiance 900 .. 1.23).

Each is read in the default ``auto`` mode (each material's MTL statements
decide its BSDF); ``materials_cornell`` and ``veach_mis`` also in the seed's
``cook-torrance`` reading (smooth dielectrics, ``cook_torrance``, mirrors),
which renders on code without the new BSDFs.

Statistic (drpt/testing.py): per block of BLOCK x BLOCK pixels and per
channel, ``z = (mean_drpt - mean_mitsuba) / sqrt(var_drpt + var_mitsuba)``,
drpt's variance from its per-pixel estimate, Mitsuba's from 8 independent
batches; ``max |z| < 4.5``. Blocks of 16 x 16 pixels at 256 spp hold 65536
samples each, so the block means are close to Gaussian even with the
heavy-tailed caustic paths through the glass and water (per-pixel intervals
at this spp are not: see ``drpt compare --control``).

Negative controls, in every case: the same statistic on drpt's image scaled
by 0.97 and by 1.03 (variance by the square) exceeds 4.5, so a 3%
brightness bias cannot pass; and for ``veach_mis`` a physical one: drpt
rendering the roughest plate with alpha 0.0625 instead of 0.1 (``Pr`` 0.25
instead of 0.316) fails against Mitsuba's unchanged scene.

Size and spp: 128 x 128 (``veach_mis`` 128 x 96, its 4:3 framing) at 256
spp for both renderers; each case takes 15-25 s on a 2-core machine (drpt
and Mitsuba together), the file ~2 minutes (116 s measured, 6 tests). Measured
at these seeds: max |z| 2.6-3.4 for the five cases; the 3% controls read
9-10 (Cornell scenes) and 22-24 (veach_mis).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from drpt.scene import load_scene
from drpt.testing import BATCHES, block_z, mitsuba_runs, render_both

pytestmark = [pytest.mark.slow, pytest.mark.mitsuba]

ZMAX = 4.5
BLOCK = 16
SPP = 256
SEED = 11
SIZES = {"materials_cornell": (128, 128), "materials_cornell_conductor": (128, 128), "veach_mis": (128, 96)}

CASES = [
    ("materials_cornell", "auto"),
    ("materials_cornell", "cook-torrance"),
    ("materials_cornell_conductor", "auto"),
    ("veach_mis", "auto"),
    ("veach_mis", "cook-torrance"),
]


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    from drpt.tools.scenegen import materials_cornell, veach_mis

    out = tmp_path_factory.mktemp("material_scenes")
    materials_cornell.main(out)
    veach_mis.main(out)
    loaded = {}

    def get(name):
        if name not in loaded:
            loaded[name] = load_scene(out / f"{name}.txt")
        return loaded[name]

    return get


def _max_z(img, var, ref, ref_var) -> float:
    return float(np.abs(block_z(img, var, ref, ref_var, block=BLOCK)).max())


@pytest.mark.parametrize("name,mode", CASES, ids=[f"{n}-{m}" for n, m in CASES])
def test_drpt_agrees_with_mitsuba(scenes, name, mode):
    scene = scenes(name)
    W, H = SIZES[name]
    r, ref, ref_var = render_both(scene, W, H, SPP, bsdf=mode, seed=SEED)
    assert np.all(np.isfinite(r.image)) and r.nonfinite == 0
    assert np.all(np.isfinite(ref))
    assert r.image.mean() > 1e-2 and ref.mean() > 1e-2  # lit, not black
    z = _max_z(r.image, r.variance, ref, ref_var)
    # negative controls: a 3% brightness bias either way is caught
    z_dark = _max_z(0.97 * r.image, 0.97**2 * r.variance, ref, ref_var)
    z_bright = _max_z(1.03 * r.image, 1.03**2 * r.variance, ref, ref_var)
    assert z_dark > ZMAX and z_bright > ZMAX, (z_dark, z_bright)
    print(f"{name} ({mode}): max |z| = {z:.2f}; x0.97: {z_dark:.2f}, x1.03: {z_bright:.2f}")
    assert z < ZMAX, f"{name} ({mode}): max |z| = {z:.2f} over {BLOCK}x{BLOCK} blocks"


def test_veach_wrong_plate_roughness_is_caught(scenes):
    """drpt renders the roughest plate at alpha 0.0625 (Pr 0.25) instead of 0.1;
    Mitsuba renders the scene as written: the block z-test must fail."""
    scene = scenes("veach_mis")
    W, H = SIZES["veach_mis"]
    from drpt.options import RenderOptions
    from drpt.render.renderer import Renderer

    runs = mitsuba_runs(scene, W, H, SPP, bsdf="auto", seed=SEED)
    ref, ref_var = runs.mean(0), runs.var(0, ddof=1) / BATCHES
    names = [m.name for m in scene.materials]
    k = names.index("plate3")
    assert abs(scene.materials[k].roughness - 0.1**0.5) < 1e-5
    materials = list(scene.materials)
    materials[k] = replace(materials[k], roughness=0.25)
    wrong = replace(scene, materials=materials)
    r = Renderer(wrong, RenderOptions(width=W, height=H, spp=SPP, seed=SEED, bsdf="auto",
                                      progress=False)).render()
    z = _max_z(r.image, r.variance, ref, ref_var)
    print(f"veach_mis, plate3 at alpha 0.0625 in drpt only: max |z| = {z:.2f}")
    assert z > ZMAX
