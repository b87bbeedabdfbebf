"""Material interpretation (drpt/materials/interpret.py): which BSDF tree each material gets.

The seed modes (phong, cook-torrance, diffuse) keep the seed renderer's
reading; ``auto`` is the MTL table of the module docs, tested here through
the real MTL parser, one row at a time.
"""

import pytest

from drpt.materials.interpret import interpret
from drpt.materials.spec import BSDFSpec, Texture, complete
from drpt.scene.model import Material
from drpt.scene.mtl import parse_mtl_text


def leaf(spec):
    """The single leaf under twosided wrappers."""
    (only,) = spec.leaves()
    return only


def mtl(text, tmp_path, name="m"):
    return parse_mtl_text(f"newmtl {name}\n{text}\n", tmp_path / "x.mtl")[name]


# ------------------------------------------------------------------ seed modes
def test_phong_energy_is_capped_and_said():
    # The course's Cornell box asks for Kd 1 and Ks 1.
    s = interpret(Material("m", kd=(1, 1, 1), ks=(1, 1, 1), ns=33), "phong")
    assert s.kind == "twosided"
    p = leaf(s)
    assert p.kind == "phong" and p["kd"] == (0.5, 0.5, 0.5) and p["ks"] == (0.5, 0.5, 0.5)
    assert s.notes and "scaled" in s.notes[0]
    ok = interpret(Material("m", kd=(0.5, 0.2, 0.1), ks=(0.4, 0.4, 0.4)), "phong")
    assert leaf(ok)["kd"] == (0.5, 0.2, 0.1) and not ok.notes


@pytest.mark.parametrize("kw", [dict(dissolve=0.5), dict(illum=4), dict(illum=7),
                                dict(transparent=(1, 1, 1))])
def test_see_through_materials_are_glass_in_seed_modes(kw):
    s = interpret(Material("g", ior=1.33, **kw), "cook-torrance")
    assert s.kind == "dielectric" and s["int_ior"] == 1.33 and s["ext_ior"] == 1.0
    assert interpret(Material("g", **kw), "phong")["int_ior"] == 1.5  # default IOR


def test_mirrors_in_seed_modes():
    assert leaf(interpret(Material("m", reflective=(0.9, 0.8, 0.7)), "phong"))["ks"] == (0.9, 0.8, 0.7)
    s = leaf(interpret(Material("m", kd=(0, 0, 0), ks=(0.5, 0.5, 0.5), illum=3), "phong"))
    assert s.kind == "mirror" and s["ks"] == (0.5, 0.5, 0.5)


def test_cook_torrance_alpha_is_roughness_squared_with_the_seeds_default():
    s = leaf(interpret(Material("c", kd=(0.9, 0.75, 0.3), roughness=0.2, metalness=0.6), "cook-torrance"))
    assert s.kind == "cook_torrance"
    assert s["alpha"] == pytest.approx(0.04) and s["metalness"] == 0.6
    d = leaf(interpret(Material("c", ns=98.0), "cook-torrance"))  # no Roughness: the seed's 0.95
    assert d["alpha"] == pytest.approx(0.95 ** 2) and d["metalness"] == 0.0
    clamped = interpret(Material("c", roughness=3.0, metalness=-1), "cook-torrance")
    assert leaf(clamped)["alpha"] == 1.0 and leaf(clamped)["metalness"] == 0.0
    assert len(clamped.notes) == 2  # both clamps are said


def test_modes():
    m = Material("m", kd=(0.2, 0.3, 0.4), ks=(0.5, 0.5, 0.5), roughness=0.5)
    assert leaf(interpret(m, "phong")).kind == "phong"
    assert leaf(interpret(m, "cook-torrance")).kind == "cook_torrance"
    assert leaf(interpret(m, "diffuse")).kind == "diffuse"
    assert leaf(interpret(Material("d", kd=(0.2, 0.3, 0.4)), "phong")).kind == "diffuse"
    with pytest.raises(ValueError):
        interpret(m, "blinn")


@pytest.mark.parametrize("mode", ["auto", "phong", "cook-torrance", "diffuse"])
def test_emission_without_kd_reflects_nothing(mode, tmp_path):
    m = mtl("Ke 10 10 10", tmp_path)
    assert leaf(interpret(m, mode))["kd"] == (0.0, 0.0, 0.0)
    lit = mtl("Ke 10 10 10\nKd 0.5 0.5 0.5", tmp_path)
    assert leaf(interpret(lit, mode))["kd"] == (0.5, 0.5, 0.5)


# ------------------------------------------------------------------ auto: the MTL table
@pytest.mark.parametrize("text, kind", [
    ("Kd 0.5 0.5 0.5", "diffuse"),
    ("Kd 0.5 0.5 0.5\nKs 0.2 0.2 0.2\nNs 50", "phong"),
    ("Kd 0.8 0.2 0.1\nPr 0.4\nPm 1", "principled"),
    ("Kd 0.8 0.2 0.1\nPm 0.5", "principled"),
    ("Kd 0.8 0.2 0.1\nPs 0.5", "principled"),
    ("Kd 0.8 0.8 0.8\nRoughness 0.3\nMentalness 0.2", "cook_torrance"),
    ("Kd 0 0 0\nKs 0.9 0.8 0.7\nillum 3", "conductor"),
    ("Ks 0.9 0.8 0.7\nillum 3\nPr 0.3", "roughconductor"),
    ("Ni 1.33\nTf 1 1 1\nillum 7", "dielectric"),
    ("Ni 1.5\nTf 0.7 0.85 1\nPr 0.3", "roughdielectric"),
    ("Ni 1.5\nd 0.2", "dielectric"),
    ("Kd 0.5 0.5 0.5\nNi 1.45\nd 1\nillum 2\nTf 1 1 1", "diffuse"),  # opaque illum: Tf is no glass
])
def test_auto_table_rows(text, kind, tmp_path):
    spec = interpret(mtl(text, tmp_path), "auto")
    assert leaf(spec).kind == kind
    two = spec.kind == "twosided"
    assert two == (kind not in ("dielectric", "roughdielectric"))  # reflective ones on both sides


def test_auto_parameters(tmp_path):
    p = leaf(interpret(mtl("Kd 0.8 0.2 0.1\nPr 0.4\nPm 1\nPc 0.5\nPcr 0.2\naniso 0.3\nNi 1.45", tmp_path)))
    assert p["base_color"] == (0.8, 0.2, 0.1) and p["roughness"] == 0.4 and p["metallic"] == 1.0
    assert p["clearcoat"] == 0.5 and p["clearcoat_gloss"] == pytest.approx(0.8)
    assert p["anisotropic"] == 0.3 and p["eta"] == 1.45
    g = leaf(interpret(mtl("Ni 1.5\nTf 0.7 0.85 1\nPr 0.3", tmp_path)))
    assert g["alpha"] == pytest.approx(0.09) and g["distribution"] == "ggx"
    assert g["specular_transmittance"] == (0.7, 0.85, 1.0) and g["int_ior"] == 1.5
    c = leaf(interpret(mtl("Ks 0.9 0.8 0.7\nillum 3\nPr 0.5", tmp_path)))
    assert c["alpha"] == pytest.approx(0.25) and c["specular_reflectance"] == (0.9, 0.8, 0.7)


def test_auto_opacity_is_a_mask(tmp_path):
    (tmp_path / "cut.png").write_bytes(b"")  # existence is enough for the parser
    s = interpret(mtl("Kd 0.5 0.5 0.5\nd 0.25", tmp_path), "auto")
    assert s.kind == "mask" and s["opacity"] == 0.25 and leaf(s).kind == "diffuse"
    t = interpret(mtl("Kd 0.5 0.5 0.5\nmap_d cut.png", tmp_path), "auto")
    assert t.kind == "mask" and isinstance(t["opacity"], Texture) and t["opacity"].fallback == 1.0


def test_auto_textures_keep_their_fallback(tmp_path):
    (tmp_path / "r.png").write_bytes(b"")
    p = leaf(interpret(mtl("Kd 0.5 0.5 0.5\nPr 0.3\nmap_Pr r.png", tmp_path)))
    assert isinstance(p["roughness"], Texture) and p["roughness"].fallback == 0.3


def test_explicit_bsdf_is_used_as_given():
    spec = BSDFSpec("roughconductor", {"material": "Au", "alpha": 0.2})
    m = Material("x", bsdf=spec)
    out = interpret(m, "auto")
    assert out.kind == "roughconductor" and out["material"] == "Au"
    assert out["distribution"] == "beckmann"  # Mitsuba's default filled in


def test_complete_rejects_what_mitsuba_would():
    with pytest.raises(ValueError, match="no parameter"):
        complete(BSDFSpec("diffuse", {"roughness": 0.3}))
    with pytest.raises(ValueError, match="unknown BSDF"):
        complete(BSDFSpec("velvet"))
    with pytest.raises(ValueError, match="nested"):
        complete(BSDFSpec("mask", {"opacity": 0.5}))
    with pytest.raises(ValueError, match="transmissive"):
        complete(BSDFSpec("twosided", children=[BSDFSpec("dielectric")]))
    with pytest.raises(ValueError, match="texture"):
        complete(BSDFSpec("mirror", {"ks": Texture("x.png")}))
