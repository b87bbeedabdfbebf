"""Material interpretation (drpt/shading.py): which BSDF each material gets."""

import pytest

from drpt.scene.model import Material
from drpt.shading import interpret


def test_phong_energy_is_capped_and_said():
    # The course's Cornell box asks for Kd 1 and Ks 1.
    s = interpret(Material("m", kd=(1, 1, 1), ks=(1, 1, 1), ns=33), "phong")
    assert s.kind == "phong" and s.kd == (0.5, 0.5, 0.5) and s.ks == (0.5, 0.5, 0.5)
    assert s.notes and "scaled" in s.notes[0]
    ok = interpret(Material("m", kd=(0.5, 0.2, 0.1), ks=(0.4, 0.4, 0.4)), "phong")
    assert ok.kd == (0.5, 0.2, 0.1) and not ok.notes


@pytest.mark.parametrize("kw", [dict(dissolve=0.5), dict(illum=4), dict(illum=7),
                                dict(transparent=(1, 1, 1))])
def test_see_through_materials_are_glass(kw):
    s = interpret(Material("g", ior=1.33, **kw), "cook-torrance")
    assert s.kind == "dielectric" and s.ior == 1.33
    assert interpret(Material("g", **kw), "phong").ior == 1.5  # default IOR


def test_mirrors():
    assert interpret(Material("m", reflective=(0.9, 0.8, 0.7)), "phong").ks == (0.9, 0.8, 0.7)
    s = interpret(Material("m", kd=(0, 0, 0), ks=(0.5, 0.5, 0.5), illum=3), "phong")
    assert s.kind == "mirror" and s.ks == (0.5, 0.5, 0.5)


def test_cook_torrance_roughness_metalness_and_defaults():
    s = interpret(Material("c", kd=(0.9, 0.75, 0.3), roughness=0.2, metalness=0.6), "cook-torrance")
    assert (s.kind, s.alpha, s.metalness) == ("cook_torrance", 0.2, 0.6)
    d = interpret(Material("c", ns=98.0), "cook-torrance")  # alpha from Ns: sqrt(2/(Ns+2))
    assert d.alpha == pytest.approx(0.1414, abs=1e-4) and d.metalness == 0.0
    clamped = interpret(Material("c", roughness=3.0, metalness=-1), "cook-torrance")
    assert clamped.alpha == 1.0 and clamped.metalness == 0.0


def test_modes():
    m = Material("m", kd=(0.2, 0.3, 0.4), ks=(0.5, 0.5, 0.5), roughness=0.5)
    assert interpret(m, "phong").kind == "phong"
    assert interpret(m, "cook-torrance").kind == "cook_torrance"
    assert interpret(m, "diffuse").kind == "diffuse"
    assert interpret(Material("d", kd=(0.2, 0.3, 0.4)), "phong").kind == "diffuse"
    with pytest.raises(ValueError):
        interpret(m, "blinn")
