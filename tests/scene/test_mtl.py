"""MTL parser: fields, defaults, textures, warnings and located errors."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

from drpt.errors import Loc, SceneError
from drpt.scene.mtl import load_mtl


def write(tmp_path: Path, text: str, name: str = "m.mtl") -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def test_all_fields(tmp_path):
    (tmp_path / "tex").mkdir()
    (tmp_path / "tex" / "wood.png").write_bytes(b"not really a png")
    p = write(tmp_path, """# header comment
newmtl red
Kd 0.9 0.1 0.1   # inline comment
Ks 0.5
Ka 1 1 1
Ns 33
Ni 1.5
d 0.25
illum 2
Roughness 0.3
Mentalness 0.7
map_Kd tex/wood.png

newmtl glow
kd 0 0 0
Le 10 10 10
Tr 0.25
Pr 0.2
Pm 0.9
newmtl ke_lower
ke 1 2 3
KE 4 5 6
""")
    mats = load_mtl(p)
    assert list(mats) == ["red", "glow", "ke_lower"]
    red = mats["red"]
    assert red.kd == (0.9, 0.1, 0.1)
    assert red.ks == (0.5, 0.5, 0.5)  # one value means gray
    assert red.ns == 33.0 and red.ior == 1.5 and red.dissolve == 0.25 and red.illum == 2
    assert red.roughness == 0.3 and red.metalness == 0.7
    assert red.map_kd == (tmp_path / "tex" / "wood.png").resolve()
    assert red.map_kd.is_absolute()
    assert red.loc == Loc(p, 2) and str(red.loc) == f"{p}:2"
    glow = mats["glow"]
    assert glow.kd == (0.0, 0.0, 0.0) and glow.emission == (10.0, 10.0, 10.0) and glow.is_emissive
    assert glow.dissolve == 0.75
    assert glow.roughness == 0.2 and glow.metalness == 0.9
    assert mats["ke_lower"].emission == (4.0, 5.0, 6.0)


def test_defaults(tmp_path):
    m = load_mtl(write(tmp_path, "newmtl plain\n"))["plain"]
    assert m.kd == (0.8, 0.8, 0.8) and m.ks == (0, 0, 0) and m.emission == (0, 0, 0)
    assert m.roughness is None and m.metalness is None and m.ior is None and m.map_kd is None
    assert m.dissolve == 1.0


def test_name_with_spaces_and_redefinition(tmp_path):
    p = write(tmp_path, "newmtl my mat\nKd 1 0 0\nnewmtl my mat\nKd 0 1 0\n")
    with pytest.warns(UserWarning, match="defined again"):
        mats = load_mtl(p)
    assert mats["my mat"].kd == (0.0, 1.0, 0.0)


def test_map_kd_options_skipped(tmp_path):
    (tmp_path / "a.png").write_bytes(b"x")
    p = write(tmp_path, "newmtl a\nmap_Kd -s 2 2 1 -clamp on a.png\n")
    with pytest.warns(UserWarning, match="options"):
        m = load_mtl(p)["a"]
    assert m.map_kd == (tmp_path / "a.png").resolve()


def test_other_maps_and_unknown_warn_once(tmp_path):
    p = write(tmp_path, "newmtl a\nmap_Bump x.png\nmap_Bump y.png\nfoo 1\nfoo 2\nbump z.png\n")
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        load_mtl(p)
    msgs = [str(w.message) for w in rec]
    assert sum("map_bump" in m for m in msgs) == 1
    assert sum("'foo'" in m for m in msgs) == 1
    assert sum("'bump'" in m for m in msgs) == 1
    assert all(":" in m for m in msgs)


@pytest.mark.parametrize(
    "text, line, fragment",
    [
        ("Kd 1 1 1\n", 1, "before any 'newmtl'"),
        ("# c\n\nnewmtl a\nKd 1 1.0.0 1\n", 4, "1.0.0"),
        ("newmtl a\nKd 1 abc 1\n", 2, "abc"),
        ("newmtl a\nNs nan\n", 2, "nan"),
        ("newmtl a\nNs inf\n", 2, "inf"),
        ("newmtl a\nKd 1 1\n", 2, "1 or 3 numbers"),
        ("newmtl a\nNs 1 2\n", 2, "expected 1 number"),
        ("newmtl a\nNs\n", 2, "expected 1 number"),
        ("newmtl a\nillum 2.5\n", 2, "integer"),
        ("newmtl\n", 1, "without a material name"),
        ("newmtl a\n\nmap_Kd missing.png\n", 3, "missing.png"),
        ("newmtl a\nmap_Kd -zz 1 a.png\n", 2, "unsupported option"),
        ("newmtl a\nmap_Kd\n", 2, "missing file name"),
        ("newmtl a\nKd spectral x.spd\n", 2, "not supported"),
    ],
)
def test_errors(tmp_path, text, line, fragment):
    p = write(tmp_path, text, "bad.mtl")
    with pytest.raises(SceneError) as e:
        load_mtl(p)
    assert f"bad.mtl:{line}:" in str(e.value)
    assert fragment in str(e.value)
    assert e.value.line == line


def test_missing_file_reported_at_reference(tmp_path):
    ref = tmp_path / "x.obj"
    with pytest.raises(SceneError) as e:
        load_mtl(tmp_path / "nope.mtl", ref=Loc(ref, 7))
    assert str(e.value).startswith(f"{ref}:7:") and "nope.mtl" in str(e.value)


def test_non_utf8(tmp_path):
    p = tmp_path / "b.mtl"
    p.write_bytes(b"newmtl a\nKd 1 1 1\n# caf\xe9\n")
    with pytest.raises(SceneError) as e:
        load_mtl(p)
    assert "b.mtl:3:" in str(e.value) and "UTF-8" in str(e.value)
