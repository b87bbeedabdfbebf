"""Each material kind rendered by drpt and by Mitsuba 3 (through the
exporter) agrees within noise: block z-scores, see drpt/testing.py.

The scene (:func:`support.materials.make`): a floor, a back wall and a ceiling light
(OBJ + MTL), one sphere of the material under test, a diffuse sphere beside it, max depth 6.
"""

import contextlib

import pytest

from drpt.testing import assert_agree, render_both
from support.materials import make, with_bsdf

pytestmark = pytest.mark.mitsuba

CASES = [
    ("phong", "phong", "phong"),
    ("phong_sharp", "phong", "phong"),
    ("ct_gold", "cook-torrance", "cook_torrance"),
    ("ct_rough", "cook-torrance", "cook_torrance"),
    ("ct_plastic", "cook-torrance", "cook_torrance"),
    ("glass", "phong", "dielectric"),
    ("mirror", "phong", "mirror"),
]


@pytest.mark.parametrize("mtl, mode, module", CASES)
def test_material_matches_mitsuba(tmp_path, mtl, mode, module):
    pytest.importorskip(f"drpt.render.bsdf.{module}")
    scene = make(tmp_path, mtl)
    with _expected_notes(mtl):
        r, ref, ref_var = render_both(scene, 48, 32, 128, max_depth=6, bsdf=mode)
    assert r.image.mean() > 0.02
    assert_agree(r, ref, ref_var)


# ------------------------------------------------------------------ composites
def _blend():
    from drpt.materials.spec import BSDFSpec

    red = BSDFSpec("twosided", children=[BSDFSpec("diffuse", {"kd": (0.8, 0.2, 0.2)})])
    gold = BSDFSpec("twosided", children=[BSDFSpec("cook_torrance", {"kd": (0.9, 0.75, 0.3), "alpha": 0.05,
                                                                     "metalness": 1.0})])
    return BSDFSpec("blendbsdf", {"weight": 0.35}, [red, gold])


def _mask_of_blend():
    from drpt.materials.spec import BSDFSpec

    return BSDFSpec("mask", {"opacity": 0.6}, [_blend()])


@pytest.mark.parametrize("make_spec", [_blend, _mask_of_blend], ids=["blendbsdf", "mask(blendbsdf)"])
def test_composites_match_mitsuba(tmp_path, make_spec):
    scene = with_bsdf(make(tmp_path, "phong"), "phong", make_spec())
    r, ref, ref_var = render_both(scene, 48, 32, 128, max_depth=6, bsdf="auto")
    assert r.image.mean() > 0.02
    assert_agree(r, ref, ref_var)


def test_mtl_dissolve_is_a_mask_that_matches_mitsuba(tmp_path):
    (tmp_path / "extra.mtl").write_text("")
    scene = make(tmp_path, "phong")
    from dataclasses import replace

    i = next(k for k, m in enumerate(scene.materials) if m.name == "phong")
    given = tuple(sorted({*scene.materials[i].given, "d"}))
    scene.materials[i] = replace(scene.materials[i], dissolve=0.3, given=given)
    with _expected_notes("phong"):
        r, ref, ref_var = render_both(scene, 48, 32, 128, max_depth=6, bsdf="auto")
    assert_agree(r, ref, ref_var)


def _expected_notes(mtl):
    """The exporter's warning for a material that needs one: "phong" (Kd 0.3 0.4 0.6, Ks
    0.5) reflects 1.1 and is scaled to 1, in drpt and in the export alike."""
    if mtl == "phong":
        return pytest.warns(UserWarning, match=r"material 'phong': Kd \+ Ks = 1.1 > 1")
    return contextlib.nullcontext()


def test_composite_negative_control(tmp_path, monkeypatch):
    """The z-test sees a blend weight off by 0.15 (drpt at 0.35, Mitsuba given 0.5)."""
    import numpy as np

    from drpt.export import mitsuba as ex
    from drpt.testing import block_z

    real = ex.bsdf_to_mitsuba

    def biased(spec):
        d = real(spec)
        if d["type"] == "blendbsdf":
            d["weight"] = 0.5
        return d

    monkeypatch.setattr(ex, "bsdf_to_mitsuba", biased)
    scene = with_bsdf(make(tmp_path, "phong"), "phong", _blend())
    r, ref, ref_var = render_both(scene, 48, 32, 128, max_depth=6, bsdf="auto")
    assert np.abs(block_z(r.image, r.variance, ref, ref_var)).max() > 4.5
